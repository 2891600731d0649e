#!/usr/bin/python3
"""The three grid schemes against each other: Cell+List, Cell+Table (the thesis' designs, 4.3)
and Cell+Sorted, on the still and dambreak setups at several scales, 1 and 2 threads, the grids
run in a rotating order in each round so that drifts of the machine hit all alike.

    /usr/bin/python3 scripts/bench-grids.py [--rounds 3] [--grids list,table,sorted] [--scales 1,2,4]
        [--particle-steps 3e6] [--overlap-ranks 2]
        [--overlap-transports messages,window] [--out results/<host>/grid_benchmark.json]
        [--png FILE]

Per run: wall time per step, ns per ordered pair (wall time / neighbour interactions, both
physics stages and the grid included), particle-steps/s and peak RSS. Per configuration: the
median of each with min..max, and each grid's speed-up over table from the ratios of the same
round. Then per grid: the 2-thread speed-up (median over setups and scales) and the bytes per
particle above the fixed cost (peak RSS slope between the smallest and largest scale). Steps per
run: --particle-steps / particles, within [--min-steps, --max-steps]. Nothing else may run
meanwhile. Runs with ranks x threads above the core count are marked oversubscribed.

Then Cell+Sorted at --overlap-ranks ranks, 1 thread, blocking and with --overlap in alternating
order per round: the exchanges' time per step (comm_s, mean over ranks), the share of it the
overlap hides (1 - overlapped / blocking, per round) of the ghost and density exchanges (the
ones it overlaps) and of all three (migration stays blocking), and the wall time per step; for
each --overlap-transports (sph --halo-transport: MPI messages, or the shared-memory window), and
for the window what its overlapped run leaves of the blocking exchanges by messages.

Then the dam break at scale 1 over a longer run (--developed-steps, 1 rank, each thread count),
Cell+Table and Cell+Sorted alternating: the short runs above see only the flow's start, where the
particles still sit in their initial lattice order, and the stored-list grids' search and id sort
grow dearer as that order decays (model/NOTES.md, "Memory order"); Cell+Sorted's cost does not.
Per report interval: each grid's time per step (the sum of its phase timers, 1 rank) and sorted
over table per round; and over the whole run, from the wall times.

With --pysph, PySPH (scripts/pysph_dambreak.py: the same dam break, spacing, time step, support
and viscosity) at each thread count, alternating with sph --grid sorted on the same case in
every round: particle-steps/s of each, and sorted over PySPH per round. PySPH's WCSPH takes 2
force evaluations per step, sph 1: both figures are given.
"""
import argparse
import itertools
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import tempfile

from script_common import git_commit, pyplot, write_json

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(os.environ.get("SPHPERF_BUILD_DIR", os.path.join(ROOT, "build")), "bin")
GRIDS = ("list", "table", "sorted")


def run_sph(grid, setup, scale, threads, ranks, steps, tmp, overlap=False, interval=None,
            transport="messages"):
    report = os.path.join(tmp, "sph.json")
    cmd = ["bash", os.path.join(ROOT, "scripts", "mpirun.sh"), "-n", str(ranks), "-t", str(threads),
           os.path.join(BIN, "sph"), "--quiet", "--grid", grid, "--setup", setup, "--scale",
           str(scale), "--threads", str(threads), "--steps", str(steps), "--interval",
           str(interval or steps), "--report", report, "--halo-transport", transport] + (
               ["--overlap"] if overlap else [])
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"bench-grids: {' '.join(cmd)} failed: {r.stderr.strip()}")
    j = json.load(open(report))
    particles = j["particles"]["field"] + j["particles"]["wall"]
    return {"step_s": j["wall_s"] / steps,
            # Per rank-thread: the wall time of all of them over the pairs they computed.
            "ns_per_pair": 1e9 * ranks * threads / j["neighbour_interactions_per_s"],
            "particle_steps_per_s": j["particle_steps_per_s"],
            "peak_rss_bytes": max(j["peak_rss_bytes"]), "particles": particles,
            "field": j["particles"]["field"],
            # The exchanges' own time (the wait for a slower neighbour apart), mean over ranks:
            # all three, and the ghost and density exchanges alone (those --overlap overlaps).
            "comm_s_per_step": j["totals"]["timers"]["comm_s"]["avg"] / steps,
            "halo_comm_s_per_step": sum(r.get("halo_comm_s", 0) for iv in j["intervals"]
                                        for r in iv["ranks"]) / ranks / steps,
            # Per interval (1 rank): its end step, simulated time and time per step, the sum of
            # the rank's phase timers (they cover the step).
            "intervals": [{"step": iv["step"], "time_s": iv["time_s"],
                           "timers_s": sum(iv["ranks"][0]["timers"].values())}
                          for iv in j["intervals"]] if ranks == 1 else [],
            # Runs of two or more threads: the core latency gauge (sph/README.md), the mean round
            # trip of a line between threads 0 and 1 and the share of its samples in intervals
            # whose mean is in the far mode (None: no reading, one thread or taking turns).
            **core_round_trip(j),
            # The binary's flags and the machine it ran on, for the benchmark's own report.
            "build": j.get("build"), "topology": j.get("topology")}


# This VM's two vCPUs pass a cache line back and forth in about 60 ns in most spells and about
# 350 ns in others (sph/NOTES.md, sessions 21 and 70); an interval whose mean round trip is
# above this is in the far mode.
FAR_ROUND_TRIP_S = 150e-9


def core_round_trip(report):
    total = samples = far = 0.0
    for iv in report["intervals"]:
        for r in iv["ranks"]:
            n = r.get("core_round_trip_samples", 0)
            if n > 0:
                total += r["core_round_trip_s"]
                samples += n
                far += n if r["core_round_trip_s"] / n > FAR_ROUND_TRIP_S else 0
    if samples == 0:
        return {"core_round_trip_s": None, "core_far_fraction": None}
    return {"core_round_trip_s": total / samples, "core_far_fraction": far / samples}


def run_pysph(scale, threads, steps):
    cmd = [sys.executable, os.path.join(ROOT, "scripts", "pysph_dambreak.py"), "--scale",
           str(scale), "--threads", str(threads), "--steps", str(steps)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"bench-grids: {' '.join(cmd)} failed: {r.stderr.strip()}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def spread(values):
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def parse_list(text, kind, name):
    try:
        values = [kind(v) for v in text.split(",")]
    except ValueError:
        sys.exit(f"bench-grids: --{name} '{text}': expected a comma-separated list of numbers")
    if not values or any(v <= 0 for v in values):
        sys.exit(f"bench-grids: --{name} '{text}': every value must be > 0")
    return values


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3, help="default 3")
    ap.add_argument("--grids", default=",".join(GRIDS), help="default list,table,sorted")
    ap.add_argument("--setups", default="still,dambreak", help="default still,dambreak")
    ap.add_argument("--scales", default="1,2,4", help="default 1,2,4")
    ap.add_argument("--threads", default="1,2", help="default 1,2")
    ap.add_argument("--ranks", default="1", help="default 1")
    ap.add_argument("--particle-steps", type=float, default=3e6, help="per run, default 3e6")
    ap.add_argument("--min-steps", type=int, default=40, help="default 40")
    ap.add_argument("--max-steps", type=int, default=400, help="default 400")
    ap.add_argument("--overlap-ranks", type=int, default=2,
                    help="ranks of the sorted --overlap comparison (default 2; 0: none)")
    ap.add_argument("--overlap-transports", default="messages,window",
                    help="sph --halo-transport of the --overlap comparison, each blocking and "
                         "overlapped (default messages,window)")
    ap.add_argument("--developed-steps", type=int, default=1200,
                    help="steps of the longer scale-1 dam break, table against sorted (default "
                         "1200; 0: none)")
    ap.add_argument("--developed-interval", type=int, default=200,
                    help="its steps per report interval (default 200)")
    ap.add_argument("--pysph", action="store_true",
                    help="also run PySPH on the dam break (install-deps.sh --with-reference-tools)")
    ap.add_argument("--pysph-scale", type=float, default=1.0, help="its scale, default 1")
    ap.add_argument("--pysph-steps", type=int, default=200, help="its timed steps, default 200")
    ap.add_argument("--out", help="JSON output (default results/<host>/grid_benchmark.json)")
    ap.add_argument("--png", help="plot (default: the JSON's path with .png)")
    ap.add_argument("--plot-only", metavar="JSON",
                    help="redraw the plot of an earlier run's JSON, run nothing")
    args = ap.parse_args()
    if args.plot_only:
        try:
            old = json.load(open(args.plot_only))
            rows, overlap_rows = old["results"], old.get("overlap", [])
            grids = list(rows[0]["grids"]) if rows else []
        except (OSError, ValueError, KeyError, IndexError) as e:
            sys.exit(f"bench-grids: --plot-only {args.plot_only}: not a grid benchmark JSON ({e})")
        plot(rows, grids, args.png or os.path.splitext(args.plot_only)[0] + ".png", overlap_rows,
             old.get("developed", []))
        return
    if args.overlap_ranks < 0 or args.overlap_ranks == 1:
        sys.exit(f"bench-grids: --overlap-ranks {args.overlap_ranks}: expected 0 (none) or >= 2")
    if args.rounds < 1 or args.min_steps < 1 or args.max_steps < args.min_steps:
        sys.exit(f"bench-grids: --rounds {args.rounds} must be >= 1 and 1 <= --min-steps "
                 f"{args.min_steps} <= --max-steps {args.max_steps}")
    if args.developed_steps < 0 or args.developed_interval < 1 or (
            args.developed_steps and args.developed_steps % args.developed_interval):
        sys.exit(f"bench-grids: --developed-steps {args.developed_steps} must be 0 or a positive "
                 f"multiple of --developed-interval {args.developed_interval}")
    transports = args.overlap_transports.split(",")
    for t in transports:
        if t not in ("messages", "window"):
            sys.exit(f"bench-grids: --overlap-transports: unknown transport '{t}' (expected "
                     "messages or window)")
    grids = args.grids.split(",")
    for g in grids:
        if g not in GRIDS:
            sys.exit(f"bench-grids: --grids: unknown grid '{g}' (expected list, table or sorted)")
    for s in args.setups.split(","):
        if s not in ("still", "dambreak"):
            sys.exit(f"bench-grids: --setups: unknown setup '{s}' (expected still or dambreak)")
    scales = parse_list(args.scales, float, "scales")
    threads = parse_list(args.threads, int, "threads")
    ranks = parse_list(args.ranks, int, "ranks")
    if args.pysph and subprocess.run([sys.executable, "-c", "import pysph"],
                                     capture_output=True).returncode != 0:
        sys.exit("bench-grids: --pysph: PySPH is not installed for " + sys.executable +
                 "; run scripts/install-deps.sh --with-reference-tools")
    if args.pysph and (not args.pysph_scale > 0 or args.pysph_steps < 1):
        sys.exit(f"bench-grids: --pysph-scale {args.pysph_scale} must be > 0 and --pysph-steps "
                 f"{args.pysph_steps} >= 1")
    if not os.access(os.path.join(BIN, "sph"), os.X_OK):
        sys.exit(f"bench-grids: {BIN}/sph missing; run scripts/build.sh first")
    out = args.out or os.path.join(ROOT, "results", socket.gethostname(), "grid_benchmark.json")
    png = args.png or os.path.splitext(out)[0] + ".png"
    cores = os.cpu_count() or 1
    configs = list(itertools.product(args.setups.split(","), scales, threads, ranks))

    # Particles per configuration from a 1-step run, for the step count.
    steps = {}
    with tempfile.TemporaryDirectory() as tmp:
        for c in configs:
            if (c[0], c[1]) not in steps:
                n = run_sph("table", c[0], c[1], 1, 1, 1, tmp)["particles"]
                steps[(c[0], c[1])] = max(args.min_steps,
                                          min(args.max_steps, math.ceil(args.particle_steps / n)))
        results = {c: {g: [] for g in grids} for c in configs}
        for rnd in range(args.rounds):
            for k, c in enumerate(configs):
                print(f"round {rnd + 1}/{args.rounds}, config {k + 1}/{len(configs)}: {c}",
                      file=sys.stderr, flush=True)
                # Rotate which grid goes first, so none always runs on a warmer machine.
                shift = (rnd + k) % len(grids)
                for g in grids[shift:] + grids[:shift]:
                    results[c][g].append(run_sph(g, *c, steps[(c[0], c[1])], tmp))
        # Blocking against overlapped exchanges, the same configuration, alternating order.
        # Per transport, in a rotating order too.
        overlap_cases = ([(c[0], c[1], t) for c in sorted({(c[0], c[1]) for c in configs})
                          for t in transports] if args.overlap_ranks else [])
        overlap_runs = {c: {False: [], True: []} for c in overlap_cases}
        for rnd in range(args.rounds):
            for k, (setup, scale, transport) in enumerate(overlap_cases):
                print(f"round {rnd + 1}/{args.rounds}, overlap {k + 1}/{len(overlap_cases)}: "
                      f"{setup} s{scale:g} at {args.overlap_ranks} ranks, {transport}",
                      file=sys.stderr, flush=True)
                for ov in ((False, True) if (rnd + k) % 2 == 0 else (True, False)):
                    overlap_runs[(setup, scale, transport)][ov].append(
                        run_sph("sorted", setup, scale, 1, args.overlap_ranks,
                                steps[(setup, scale)], tmp, overlap=ov, transport=transport))
        # The longer dam break, table against sorted, alternating order.
        developed = ("table" in grids and "sorted" in grids and args.developed_steps > 0)
        developed_runs = {t: {"table": [], "sorted": []} for t in (threads if developed else [])}
        for rnd in range(args.rounds):
            for k, t in enumerate(developed_runs):
                print(f"round {rnd + 1}/{args.rounds}, developed flow {k + 1}/"
                      f"{len(developed_runs)}: dambreak s1, {args.developed_steps} steps, {t} "
                      f"thread(s)", file=sys.stderr, flush=True)
                for g in (("table", "sorted") if (rnd + k) % 2 == 0 else ("sorted", "table")):
                    developed_runs[t][g].append(
                        run_sph(g, "dambreak", 1.0, t, 1, args.developed_steps, tmp,
                                interval=args.developed_interval))
        pysph_runs = {t: {"pysph": [], "sorted": []} for t in (threads if args.pysph else [])}
        for rnd in range(args.rounds):
            for k, t in enumerate(pysph_runs):
                print(f"round {rnd + 1}/{args.rounds}, PySPH {k + 1}/{len(pysph_runs)}: dambreak "
                      f"s{args.pysph_scale:g}, {t} thread(s)", file=sys.stderr, flush=True)
                for code in (("pysph", "sorted") if (rnd + k) % 2 == 0 else ("sorted", "pysph")):
                    if code == "sorted":
                        pysph_runs[t][code].append(run_sph("sorted", "dambreak", args.pysph_scale,
                                                           t, 1, args.pysph_steps, tmp))
                    else:
                        pysph_runs[t][code].append(run_pysph(args.pysph_scale, t,
                                                             args.pysph_steps))

    rows = []
    print(f"\n{'setup':9s} {'scale':>5s} {'thr':>3s} {'rk':>3s} {'particles':>9s} {'steps':>5s} "
          + " ".join(f"{g + ' ms':>10s} {'ns/pair':>7s}" for g in grids)
          + ("  sorted/table" if "sorted" in grids and "table" in grids else ""))
    for c in configs:
        runs = results[c]
        row = {"setup": c[0], "scale": c[1], "threads": c[2], "ranks": c[3],
               "oversubscribed": c[2] * c[3] > cores, "particles": runs[grids[0]][0]["particles"],
               "steps": steps[(c[0], c[1])], "rounds": args.rounds, "grids": {}}
        for g in grids:
            row["grids"][g] = {key: spread([r[key] for r in runs[g]])
                               for key in ("step_s", "ns_per_pair", "particle_steps_per_s",
                                           "peak_rss_bytes")}
            # Per run, in round order: the time per step and, at 2 threads or more, the core
            # latency gauge's mean round trip and far share (the mode each run ran in).
            row["grids"][g]["runs"] = [
                {"step_s": r["step_s"], "core_round_trip_s": r["core_round_trip_s"],
                 "core_far_fraction": r["core_far_fraction"]} for r in runs[g]]
            if g != "table" and "table" in grids:
                row["grids"][g]["speedup_over_table"] = spread(
                    [t["step_s"] / r["step_s"] for r, t in zip(runs[g], runs["table"])])
        rows.append(row)
        line = f"{c[0]:9s} {c[1]:5g} {c[2]:3d} {c[3]:3d} {row['particles']:9d} {row['steps']:5d} "
        line += " ".join(f"{row['grids'][g]['step_s']['median'] * 1e3:10.2f} "
                         f"{row['grids'][g]['ns_per_pair']['median']:7.1f}" for g in grids)
        if "sorted" in grids and "table" in grids:
            s = row["grids"]["sorted"]["speedup_over_table"]
            line += f"  {s['median']:.2f} ({s['min']:.2f}..{s['max']:.2f})"
        print(line + ("  (oversubscribed)" if row["oversubscribed"] else ""))

    summary = {}
    for g in grids:
        entry = {}
        two = [(a, b) for a in rows for b in rows
               if (a["setup"], a["scale"], a["ranks"]) == (b["setup"], b["scale"], b["ranks"])
               and a["threads"] == 1 and b["threads"] == 2 and not b["oversubscribed"]]
        if two:
            entry["two_thread_speedup"] = spread(
                [a["grids"][g]["step_s"]["median"] / b["grids"][g]["step_s"]["median"]
                 for a, b in two])
            # The same from the 2-thread runs of one core-latency mode alone (the gauge's
            # intervals all near, or all far), where a configuration has any.
            for mode, keep in (("near", lambda f: f == 0), ("far", lambda f: f == 1)):
                ratios = []
                for a, b in two:
                    key = (b["setup"], b["scale"], b["threads"], b["ranks"])
                    steps_in_mode = [r["step_s"] for r in results[key][g]
                                     if r["core_far_fraction"] is not None
                                     and keep(r["core_far_fraction"])]
                    if steps_in_mode:
                        ratios.append(a["grids"][g]["step_s"]["median"] /
                                      statistics.median(steps_in_mode))
                if ratios:
                    entry[f"two_thread_speedup_{mode}_core_latency"] = spread(ratios)
                    entry[f"two_thread_speedup_{mode}_core_latency"]["configurations"] = \
                        len(ratios)
            gauged = [r for b in (b for _, b in two)
                      for r in results[(b["setup"], b["scale"], b["threads"], b["ranks"])][g]
                      if r["core_round_trip_s"] is not None]
            if gauged:
                entry["two_thread_core_round_trip_s"] = spread(
                    [r["core_round_trip_s"] for r in gauged])
                entry["two_thread_runs_far_core_latency"] = sum(
                    r["core_far_fraction"] == 1 for r in gauged)
                entry["two_thread_runs_gauged"] = len(gauged)
        one = [r for r in rows if r["threads"] == 1 and r["ranks"] == 1]
        if one:
            entry["ns_per_pair_1_thread"] = spread(
                [r["grids"][g]["ns_per_pair"]["median"] for r in one])
        per_setup = []
        for setup in {r["setup"] for r in one}:
            mine = sorted((r for r in one if r["setup"] == setup), key=lambda r: r["scale"])
            if len(mine) >= 2 and mine[-1]["particles"] > mine[0]["particles"]:
                lo, hi = mine[0], mine[-1]
                per_setup.append(
                    (hi["grids"][g]["peak_rss_bytes"]["median"] -
                     lo["grids"][g]["peak_rss_bytes"]["median"]) /
                    (hi["particles"] - lo["particles"]))
        if per_setup:
            entry["bytes_per_particle_above_fixed"] = spread(per_setup)
        summary[g] = entry
    print()
    for g, e in summary.items():
        parts = []
        if "ns_per_pair_1_thread" in e:
            parts.append(f"ns/pair at 1 thread {e['ns_per_pair_1_thread']['median']:.1f} "
                         f"({e['ns_per_pair_1_thread']['min']:.1f}..{e['ns_per_pair_1_thread']['max']:.1f})")
        if "two_thread_speedup" in e:
            parts.append(f"2-thread speed-up {e['two_thread_speedup']['median']:.2f} "
                         f"({e['two_thread_speedup']['min']:.2f}..{e['two_thread_speedup']['max']:.2f})")
            for mode in ("near", "far"):
                m = e.get(f"two_thread_speedup_{mode}_core_latency")
                if m:
                    parts.append(f"{mode} core latency {m['median']:.2f} "
                                 f"({m['min']:.2f}..{m['max']:.2f}, {m['configurations']} "
                                 f"configurations)")
            if "two_thread_core_round_trip_s" in e:
                rt = e["two_thread_core_round_trip_s"]
                parts.append(f"core round trip {rt['median'] * 1e9:.0f} ns "
                             f"({rt['min'] * 1e9:.0f}..{rt['max'] * 1e9:.0f}; "
                             f"{e['two_thread_runs_far_core_latency']} of "
                             f"{e['two_thread_runs_gauged']} 2-thread runs far)")
        if "bytes_per_particle_above_fixed" in e:
            parts.append(f"bytes/particle above fixed {e['bytes_per_particle_above_fixed']['median']:.0f}")
        print(f"{g:6s}: " + ", ".join(parts))

    overlap_rows = []
    if overlap_cases:
        print(f"\nCell+Sorted at {args.overlap_ranks} ranks: exchanges per step, blocking vs --overlap")
        print(f"{'setup':9s} {'scale':>5s} {'transport':9s} {'halo us blk':>11s} {'ovl':>6s} "
              f"{'hidden (ghosts+density)':>24s} {'all exchanges':>14s} {'step ms (blk/ovl)':>18s}")
    for (setup, scale, transport) in overlap_cases:
        blk = overlap_runs[(setup, scale, transport)][False]
        ovl = overlap_runs[(setup, scale, transport)][True]
        keys = ("comm_s_per_step", "halo_comm_s_per_step", "step_s")

        def hidden(key):
            return spread([1 - o[key] / b[key] for b, o in zip(blk, ovl) if b[key] > 0])

        row = {"setup": setup, "scale": scale, "halo_transport": transport,
               "ranks": args.overlap_ranks, "threads": 1,
               "oversubscribed": args.overlap_ranks > cores, "steps": steps[(setup, scale)],
               "rounds": args.rounds,
               "blocking": {k: spread([r[k] for r in blk]) for k in keys},
               "overlap": {k: spread([r[k] for r in ovl]) for k in keys},
               # Per round: the share of the blocking exchanges' time the overlapped run exposes
               # no more: of the ghost and density exchanges, and of all three.
               "hidden_fraction": hidden("halo_comm_s_per_step"),
               "hidden_fraction_all_exchanges": hidden("comm_s_per_step")}
        # Per round, what the overlapped run leaves of the blocking exchanges by messages: the
        # transport's share and the overlap's together.
        by_messages = overlap_runs.get((setup, scale, "messages"), {}).get(False, [])
        if transport != "messages" and by_messages:
            key = "halo_comm_s_per_step"
            row["left_of_blocking_messages"] = spread(
                [o[key] / b[key] for b, o in zip(by_messages, ovl) if b[key] > 0])
        overlap_rows.append(row)
        h, a = row["hidden_fraction"], row["hidden_fraction_all_exchanges"]
        print(f"{setup:9s} {scale:5g} {transport:9s} "
              f"{row['blocking']['halo_comm_s_per_step']['median'] * 1e6:11.2f} "
              f"{row['overlap']['halo_comm_s_per_step']['median'] * 1e6:6.2f} "
              f"{100 * h['median']:9.1f} % ({100 * h['min']:.0f}..{100 * h['max']:.0f} %) "
              f"{100 * a['median']:12.1f} % "
              f"{row['blocking']['step_s']['median'] * 1e3:8.2f} / "
              f"{row['overlap']['step_s']['median'] * 1e3:.2f}")

    developed_rows = []
    for t, runs in developed_runs.items():
        tab, srt = runs["table"], runs["sorted"]
        per_interval = []
        for n, iv in enumerate(tab[0]["intervals"]):
            steps_in = iv["step"] - (tab[0]["intervals"][n - 1]["step"] if n else 0)
            per_interval.append({
                "step": iv["step"], "time_s": iv["time_s"],
                "table_step_s": spread([r["intervals"][n]["timers_s"] / steps_in for r in tab]),
                "sorted_step_s": spread([r["intervals"][n]["timers_s"] / steps_in for r in srt]),
                "speedup_over_table": spread([a["intervals"][n]["timers_s"] /
                                              b["intervals"][n]["timers_s"]
                                              for a, b in zip(tab, srt)])})
        developed_rows.append({
            "setup": "dambreak", "scale": 1.0, "threads": t, "ranks": 1,
            "steps": args.developed_steps, "interval": args.developed_interval,
            "rounds": args.rounds, "particles": tab[0]["particles"],
            "per_interval": per_interval,
            "whole_run": {"table_step_s": spread([r["step_s"] for r in tab]),
                          "sorted_step_s": spread([r["step_s"] for r in srt]),
                          "speedup_over_table": spread([a["step_s"] / b["step_s"]
                                                        for a, b in zip(tab, srt)])}})
    if developed_rows:
        print(f"\nDam break, scale 1, {args.developed_steps} steps: Cell+Sorted over Cell+Table per "
              f"step, per interval of {args.developed_interval} steps (median, min..max of the rounds)")
        for row in developed_rows:
            cells = [f"to {iv['time_s']:g} s {iv['speedup_over_table']['median']:.2f}"
                     for iv in row["per_interval"]]
            w = row["whole_run"]["speedup_over_table"]
            print(f"  {row['threads']} thread(s): " + ", ".join(cells) +
                  f"; whole run {w['median']:.2f} ({w['min']:.2f}..{w['max']:.2f})")

    pysph_rows = []
    for t, runs in pysph_runs.items():
        row = {"setup": "dambreak", "scale": args.pysph_scale, "threads": t, "ranks": 1,
               "steps": args.pysph_steps, "rounds": args.rounds,
               "fluid": runs["pysph"][0]["fluid"],
               "pysph": {"particle_steps_per_s": spread([r["particle_steps_per_s"]
                                                         for r in runs["pysph"]]),
                         "evaluations_per_step": 2},
               "sorted": {"particle_steps_per_s": spread([r["particle_steps_per_s"]
                                                          for r in runs["sorted"]]),
                          "evaluations_per_step": 1},
               "sorted_over_pysph": spread([s_["particle_steps_per_s"] / p["particle_steps_per_s"]
                                            for s_, p in zip(runs["sorted"], runs["pysph"])])}
        pysph_rows.append(row)
    if pysph_rows:
        print(f"\nPySPH (WCSPH, 2 evaluations per step) against sph --grid sorted (1), dambreak "
              f"s{args.pysph_scale:g}, particle-steps/s:")
        for row in pysph_rows:
            p, q, r = (row["pysph"]["particle_steps_per_s"], row["sorted"]["particle_steps_per_s"],
                       row["sorted_over_pysph"])
            print(f"  {row['threads']} thread(s): PySPH {p['median']:.3g} ({p['min']:.3g}.."
                  f"{p['max']:.3g}), sorted {q['median']:.3g}; sorted / PySPH {r['median']:.2f} "
                  f"({r['min']:.2f}..{r['max']:.2f}) per step, {r['median'] / 2:.2f} per force "
                  f"evaluation")

    commit = git_commit(ROOT)
    first = results[configs[0]][grids[0]][0]
    report = {"schema": 5, "benchmark": "grid_comparison", "host": socket.gethostname(),
              "git_commit": commit, "build": first["build"], "topology": first["topology"],
              "cores": cores, "particle_steps_per_run": args.particle_steps,
              "results": rows, "summary": summary, "overlap": overlap_rows,
              "developed": developed_rows, "pysph": pysph_rows}
    write_json(out, report)
    plot(rows, grids, png, overlap_rows, developed_rows)


def plot(rows, grids, png, overlap_rows, developed_rows=()):
    """ns per ordered pair per configuration and grid (1 rank), medians with min..max bars; the
    ghost and density exchanges per step, blocking against --overlap; and sorted over table per
    interval of the longer dam break."""
    plt = pyplot("bench-grids")
    if plt is None:
        return
    panels = 2 + (1 if overlap_rows else 0) + (1 if developed_rows else 0)
    fig, axes = plt.subplots(1, panels, figsize=(5.5 * panels, 4.2))
    axes[1].sharey(axes[0])
    for ax, t in zip(axes, (1, 2)):
        sel = [r for r in rows if r["threads"] == t and r["ranks"] == 1]
        width = 0.8 / max(1, len(grids))
        for k, g in enumerate(grids):
            med = [r["grids"][g]["ns_per_pair"]["median"] for r in sel]
            lo = [m - r["grids"][g]["ns_per_pair"]["min"] for m, r in zip(med, sel)]
            hi = [r["grids"][g]["ns_per_pair"]["max"] - m for m, r in zip(med, sel)]
            xs = [i + (k - (len(grids) - 1) / 2) * width for i in range(len(sel))]
            ax.bar(xs, med, width, yerr=[lo, hi], capsize=2, label=g)
        ax.set_xticks(range(len(sel)))
        ax.set_xticklabels([f"{r['setup']}\ns{r['scale']:g}" for r in sel], fontsize=8)
        ax.set_title(f"{t} thread{'s' if t > 1 else ''}, 1 rank")
        ax.axhline(10, color="k", lw=0.8, ls="--")
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("ns per ordered pair x threads (wall, both stages)")
    axes[0].legend()
    if overlap_rows:
        ax = axes[2]
        cases = sorted({(r["setup"], r["scale"]) for r in overlap_rows},
                       key=lambda c: [(r["setup"], r["scale"]) for r in overlap_rows].index(c))
        found = [r.get("halo_transport", "messages") for r in overlap_rows]
        kinds = [t for t in ("messages", "window") if t in found]
        bars = [(t, mode) for t in kinds for mode in ("blocking", "overlap")]
        width = 0.8 / len(bars)
        for k, (t, mode) in enumerate(bars):
            xs, med, lo, hi = [], [], [], []
            for x, c in enumerate(cases):
                r = next((r for r in overlap_rows if (r["setup"], r["scale"]) == c
                          and r.get("halo_transport", "messages") == t), None)
                if r is None:
                    continue
                m = 1e6 * r[mode]["halo_comm_s_per_step"]["median"]
                xs.append(x + (k - (len(bars) - 1) / 2) * width)
                med.append(m)
                lo.append(m - 1e6 * r[mode]["halo_comm_s_per_step"]["min"])
                hi.append(1e6 * r[mode]["halo_comm_s_per_step"]["max"] - m)
            ax.bar(xs, med, width, yerr=[lo, hi], capsize=2,
                   label=f"{t}, {'blocking' if mode == 'blocking' else 'overlapped (--overlap)'}")
        for x, c in enumerate(cases):
            rs = [r for r in overlap_rows if (r["setup"], r["scale"]) == c]
            top = 1e6 * max(r[m]["halo_comm_s_per_step"]["max"] for r in rs
                            for m in ("blocking", "overlap"))
            label = " / ".join(f"{100 * r['hidden_fraction']['median']:.0f}" for r in rs)
            ax.annotate(label + " %", (x, top), ha="center", va="bottom", fontsize=7)
        ax.set_yscale("log")
        ax.set_xticks(list(range(len(cases))))
        ax.set_xticklabels([f"{c[0]}\ns{c[1]:g}" for c in cases], fontsize=8)
        ax.set_ylabel("ghost + density exchanges, us per step (log)")
        ax.set_title(f"Cell+Sorted, {overlap_rows[0]['ranks']} ranks: hidden share above bars "
                     f"({' / '.join(kinds)})", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    if developed_rows:
        ax = axes[-1]
        for row in developed_rows:
            ts = [iv["time_s"] for iv in row["per_interval"]]
            med = [iv["speedup_over_table"]["median"] for iv in row["per_interval"]]
            lo = [m - iv["speedup_over_table"]["min"] for m, iv in zip(med, row["per_interval"])]
            hi = [iv["speedup_over_table"]["max"] - m for m, iv in zip(med, row["per_interval"])]
            ax.errorbar(ts, med, yerr=[lo, hi], marker="o", capsize=2,
                        label=f"{row['threads']} thread{'s' if row['threads'] > 1 else ''} "
                              f"(whole run {row['whole_run']['speedup_over_table']['median']:.2f}x)")
        ax.axhline(4, color="k", lw=0.8, ls="--")
        ax.set_xlabel("simulated time at the interval's end, s")
        ax.set_ylabel("Cell+Sorted over Cell+Table, per step")
        ax.set_title(f"dam break s1, {developed_rows[0]['steps']} steps, 1 rank (dashed: 4x)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Grid schemes: time per neighbour interaction (dashed: 10 ns target)")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    print(f"written {png}")


if __name__ == "__main__":
    main()
