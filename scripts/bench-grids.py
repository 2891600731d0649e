#!/usr/bin/env python3
"""Cell+Table against Cell+List, as thesis 4.3: time per step on the still and dambreak setups
at scale 1 and 2, with 1 and 2 threads and 1 and 2 ranks, the two grids run alternately in
each round so that drifts of the machine hit both alike.

    python3 scripts/bench-grids.py [--rounds 3] [--steps 300] [--out results/<host>/grid_benchmark.json]

Reports, per configuration, the median time per step of each grid, the List/Table ratio of
each round (> 1: Table faster) as median with min..max, and the grid-maintenance and
pair-search shares. Nothing else may run meanwhile. Runs with ranks x threads above the core
count are marked oversubscribed: their times measure contention as much as the code.
"""
import argparse
import itertools
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(os.environ.get("SPHPERF_BUILD_DIR", os.path.join(ROOT, "build")), "bin")


def run_sph(grid, setup, scale, threads, ranks, steps, tmp):
    report = os.path.join(tmp, "sph.json")
    cmd = ["bash", os.path.join(ROOT, "scripts", "mpirun.sh"), "-n", str(ranks), "-t", str(threads),
           os.path.join(BIN, "sph"), "--quiet", "--grid", grid, "--setup", setup, "--scale",
           str(scale), "--threads", str(threads), "--steps", str(steps), "--interval",
           str(steps), "--report", report]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"bench-grids: {' '.join(cmd)} failed: {r.stderr.strip()}")
    j = json.load(open(report))
    timers = j["totals"]["timers"]
    return {"step_s": j["wall_s"] / steps, "grid_s": timers["grid_s"]["max"] / steps,
            "pairs_s": timers["pairs_s"]["max"] / steps, "particles": j["particles"]["field"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--setups", default="still,dambreak")
    ap.add_argument("--scales", default="1,2")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--ranks", default="1,2")
    ap.add_argument("--out", help="JSON output (default results/<host>/grid_benchmark.json)")
    args = ap.parse_args()
    if args.rounds < 1 or args.steps < 1:
        sys.exit(f"bench-grids: --rounds {args.rounds} and --steps {args.steps} must be >= 1")
    if not os.access(os.path.join(BIN, "sph"), os.X_OK):
        sys.exit(f"bench-grids: {BIN}/sph missing; run scripts/build.sh first")
    out = args.out or os.path.join(ROOT, "results", socket.gethostname(), "grid_benchmark.json")
    cores = os.cpu_count() or 1
    configs = list(itertools.product(args.setups.split(","), [float(s) for s in args.scales.split(",")],
                                     [int(t) for t in args.threads.split(",")],
                                     [int(r) for r in args.ranks.split(",")]))
    results = {c: {"list": [], "table": []} for c in configs}
    with tempfile.TemporaryDirectory() as tmp:
        for rnd in range(args.rounds):
            for k, c in enumerate(configs):
                print(f"round {rnd + 1}/{args.rounds}, config {k + 1}/{len(configs)}: {c}",
                      file=sys.stderr)
                # Alternate which grid goes first, so neither always runs on a warmer machine.
                order = ["list", "table"] if (rnd + k) % 2 == 0 else ["table", "list"]
                for g in order:
                    results[c][g].append(run_sph(g, *c, args.steps, tmp))

    rows = []
    print(f"\n{'setup':9s} {'scale':>5s} {'thr':>3s} {'rk':>3s} {'particles':>9s} "
          f"{'list ms/step':>12s} {'table ms/step':>13s} {'List/Table':>10s} {'min..max':>12s} "
          f"{'grid% L/T':>10s}")
    for c in configs:
        lst, tab = results[c]["list"], results[c]["table"]
        ratios = [a["step_s"] / b["step_s"] for a, b in zip(lst, tab)]
        med = lambda v, key: statistics.median(x[key] for x in v)
        row = {"setup": c[0], "scale": c[1], "threads": c[2], "ranks": c[3],
               "oversubscribed": c[2] * c[3] > cores, "particles": lst[0]["particles"],
               "steps": args.steps, "rounds": args.rounds,
               "list_step_s": med(lst, "step_s"), "table_step_s": med(tab, "step_s"),
               "list_grid_s": med(lst, "grid_s"), "table_grid_s": med(tab, "grid_s"),
               "list_pairs_s": med(lst, "pairs_s"), "table_pairs_s": med(tab, "pairs_s"),
               "list_over_table": {"median": statistics.median(ratios), "min": min(ratios),
                                   "max": max(ratios)}}
        rows.append(row)
        print(f"{c[0]:9s} {c[1]:5g} {c[2]:3d} {c[3]:3d} {row['particles']:9d} "
              f"{row['list_step_s'] * 1e3:12.2f} {row['table_step_s'] * 1e3:13.2f} "
              f"{row['list_over_table']['median']:10.3f} "
              f"{row['list_over_table']['min']:.3f}..{row['list_over_table']['max']:.3f} "
              f"{100 * row['list_grid_s'] / row['list_step_s']:4.1f}/"
              f"{100 * row['table_grid_s'] / row['table_step_s']:4.1f}"
              f"{'  (oversubscribed)' if row['oversubscribed'] else ''}")
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    report = {"schema": 1, "benchmark": "grid_comparison", "host": socket.gethostname(),
              "git_commit": commit, "cores": cores, "results": rows}
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out + ".tmp", "w") as f:
        json.dump(report, f, indent=2)
    os.replace(out + ".tmp", out)
    print(f"written {out}")


if __name__ == "__main__":
    main()
