#!/usr/bin/python3
"""Does a step cost more than its interactions? A scale sweep tells: the same setup at several
scales, per grid, in rotating order, and a fit of each busy rank's compute per step against the
work it counted, per unit of the host's speed.

    /usr/bin/python3 scripts/scale-sweep.py [--grids list,table,sorted] [--setup dambreak]
        [--scales 0.25,0.35,0.5,0.7,1,1.4,2] [--ranks 2] [--threads 1] [--rounds 3]
        [--steps 300 | --froude-time T] [--interval 50] [--out results/<host>/scale_sweep.json]
        [--png FILE]
    /usr/bin/python3 scripts/scale-sweep.py --fit-only REPORT.json [...] [--out FILE] [--png FILE]

Per report interval (the first dropped: the first steps fill the caches), the busiest rank's
compute per step (every phase timer but comm, wait, output and rebalance: what the model calls
compute) over its speed-gauge factor (its gauge's CPU seconds per sample over the median of all
intervals'; sph --speed-gauge-every, so a slow spell of the host is not read as a cost), and the
interactions and wall particles it counted. Per grid, weighted least squares (each point
relative to its own cost, so small scales count as much as large ones) of three forms:
interactions alone, interactions + a constant per step, interactions + a cost per wall
particle; for each the coefficients, the relative rms residual and the median residual per
scale. A form is right for extrapolation when its residuals stay flat over the scales: the model
(sphmodel calibrate) can only pick a term its calibration runs' scales can tell apart from their
noise (model/NOTES.md, sessions 52 and 54). --fit-only fits reports already measured. Nothing else
may run meanwhile.

The memory order: with --froude-time T every scale runs to the same Froude time (sph --end-time
T sqrt(scale)), and per grid and scale the busiest rank's search (grid, search and id sort timers)
and pair loops (comp_s) per interaction at one host speed, and its descents per interaction (the
search's neighbours found right after one of larger id: the memory order lost), are read at five
Froude times spanning what every scale covers (linear between interval midpoints, the median over
rounds), with the search's rise from the first to the last. A Froude-time cost profile measured at
one scale carries over to another only if that rise is the same at both (model/NOTES.md, session
55). With --froude-time the three forms above read that rise too: fit them on --steps runs.
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

import numpy

from script_common import InputError, git_commit, load_report, pyplot, write_json

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(os.environ.get("SPHPERF_BUILD_DIR", os.path.join(ROOT, "build")), "bin")
SCHEMA = 1
NOT_COMPUTE = {"comm_s", "wait_s", "output_s", "rebalance_s"}
SEARCH = ("grid_s", "pairs_s", "idsort_s")  # finding the neighbours (and ordering the lists)
CHECKPOINTS = 5  # Froude times at which the memory order is compared across scales
FORMS = {"interactions": ("interactions",), "interactions+const": ("interactions", "const"),
         "interactions+walls": ("interactions", "walls")}


def positive_list(text, what, kind=float):
    try:
        values = [kind(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--{what} '{text}' is not a comma-separated list of numbers")
    if not values or any(not (v > 0) for v in values):
        raise InputError(f"--{what} '{text}': expected positive numbers")
    return values


def run_sph(grid, setup, scale, ranks, threads, length, interval, report):
    """length: ("--steps", N) or ("--end-time", seconds)."""
    cmd = ["bash", os.path.join(ROOT, "scripts", "mpirun.sh"), "-n", str(ranks), "-t", str(threads),
           os.path.join(BIN, "sph"), "--quiet", "--grid", grid, "--setup", setup, "--scale",
           f"{scale:g}", "--threads", str(threads), length[0], f"{length[1]:g}", "--interval",
           str(interval), "--report", report]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"scale-sweep.py: sph failed ({' '.join(cmd)}): {r.stderr.strip()}")


def points_of(path, doc):
    """The busiest rank's per-step figures of every interval but the first."""
    try:
        cfg = doc["config"]
        grid, scale = cfg["grid"], float(cfg["scale"])
        dt = cfg.get("dt")
        pts = []
        for iv in doc["intervals"][1:]:
            rk = max(iv["ranks"], key=lambda r: r["interactions"])
            steps = rk["steps"]
            if steps <= 0 or rk["interactions"] <= 0:
                continue
            gauge = rk["gauge_cpu_s"] / rk["gauge_samples"] if rk.get("gauge_samples") else None
            timers = rk["timers"]
            compute = sum(v for k, v in timers.items() if k not in NOT_COMPUTE) / steps
            p = {"grid": grid, "scale": scale, "interactions": rk["interactions"],
                 "walls": rk["virtual"], "field": rk["field"], "compute_s": compute,
                 "gauge_s": gauge, "report": path}
            # The memory order's part (reports of sph: the interval's end time and its step).
            if dt and "time_s" in iv and "descents" in rk:
                p["froude_t"] = (iv["time_s"] - 0.5 * steps * float(dt)) / scale ** 0.5
                p["search_s"] = sum(timers.get(k, 0.0) for k in SEARCH) / steps
                p["pair_loops_s"] = timers["comp_s"] / steps
                p["descents"] = rk["descents"]
            pts.append(p)
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"{path}: not a usable sph report (missing or bad {e})")
    if not pts:
        raise InputError(f"{path}: no interval after the first with a busy rank "
                         f"(run more steps than --interval)")
    return pts


def column(p, term):
    return {"interactions": p["interactions"], "const": 1.0, "walls": p["walls"]}[term]


UNITS = {"interactions": ("ns_per_interaction", 1e9), "const": ("us_per_step", 1e6),
         "walls": ("ns_per_wall_particle", 1e9)}


def fit(pts):
    """Each form's coefficients and residuals; the points at one host speed."""
    gauges = [p["gauge_s"] for p in pts if p["gauge_s"]]
    reference = statistics.median(gauges) if len(gauges) == len(pts) else None
    for p in pts:
        p["speed"] = p["gauge_s"] / reference if reference else 1.0
        p["compute_at_one_speed_s"] = p["compute_s"] / p["speed"]
    scales = sorted({p["scale"] for p in pts})
    out = {"gauge_applied": reference is not None, "scales": scales, "forms": {}}
    ys = numpy.array([p["compute_at_one_speed_s"] for p in pts])
    for name, terms in FORMS.items():
        # Each row divided by its own cost: least squares of the relative residual.
        X = numpy.array([[column(p, t) for t in terms] for p in pts]) / ys[:, None]
        coef, _, rank, _ = numpy.linalg.lstsq(X, numpy.ones(len(pts)), rcond=None)
        if rank < len(terms):
            out["forms"][name] = {"identifiable": False}
            continue
        res = X @ coef - 1
        out["forms"][name] = {
            "identifiable": True,
            "coefficients": {UNITS[t][0]: float(c) * UNITS[t][1] for c, t in zip(coef, terms)},
            "relative_rms_residual": float(numpy.sqrt(numpy.mean(res ** 2))),
            "median_residual_by_scale": {f"{s:g}": float(statistics.median(
                r for r, p in zip(res, pts) if p["scale"] == s)) for s in scales}}
    out["by_scale"] = [{
        "scale": s,
        "points": sum(1 for p in pts if p["scale"] == s),
        "interactions_per_step": statistics.median(p["interactions"] for p in pts if p["scale"] == s),
        "walls": statistics.median(p["walls"] for p in pts if p["scale"] == s),
        "ns_per_interaction_at_one_speed": 1e9 * statistics.median(
            p["compute_at_one_speed_s"] / p["interactions"] for p in pts if p["scale"] == s)}
        for s in scales]
    if all("froude_t" in p for p in pts):
        out["memory_order"] = memory_order(pts, scales)
    return out


def memory_order(pts, scales):
    """Per scale, the search's and pair loops' cost and the descents per interaction at common
    Froude times (at one host speed; the median over the scale's reports)."""
    by_report = {}
    for p in pts:
        by_report.setdefault(p["report"], []).append(p)
    series = {}
    for ps in by_report.values():
        ps.sort(key=lambda p: p["froude_t"])
        # Each interval's speed as the median over +-1 interval, as sphmodel calibrate takes it
        # (one gauge sample disturbed by a host interrupt reads 1.3-4 times the others).
        window = [statistics.median(p["speed"] for p in ps[max(0, k - 1):k + 2])
                  for k in range(len(ps))]
        for p, w in zip(ps, window):
            p["window_speed"] = w
        series.setdefault(ps[0]["scale"], []).append(ps)
    lo = max(ps[0]["froude_t"] for runs in series.values() for ps in runs)
    hi = min(ps[-1]["froude_t"] for runs in series.values() for ps in runs)
    if not hi > lo:
        return {"note": "the scales' reports share no span of Froude time"}
    times = [lo + (hi - lo) * k / (CHECKPOINTS - 1) for k in range(CHECKPOINTS)]
    fields = {"search_ns_per_interaction":
                  lambda p: 1e9 * p["search_s"] / p["window_speed"] / p["interactions"],
              "pair_loops_ns_per_interaction":
                  lambda p: 1e9 * p["pair_loops_s"] / p["window_speed"] / p["interactions"],
              "descents_per_interaction": lambda p: p["descents"] / p["interactions"]}
    out = {"froude_time_s": times, "by_scale": []}
    for s in scales:
        row = {"scale": s, "reports": len(series[s])}
        for name, f in fields.items():
            row[name] = [statistics.median(
                float(numpy.interp(t, [p["froude_t"] for p in ps], [f(p) for p in ps]))
                for ps in series[s]) for t in times]
        row["search_rise_ns_per_interaction"] = (row["search_ns_per_interaction"][-1]
                                                 - row["search_ns_per_interaction"][0])
        out["by_scale"].append(row)
    return out


def plot(doc, png):
    plt = pyplot("scale-sweep.py")
    if plt is None:
        return
    orders = {grid: g["memory_order"] for grid, g in doc["grids"].items()
              if g.get("memory_order", {}).get("by_scale")}
    fig, axes = plt.subplots(1, 2 if orders else 1, figsize=(13 if orders else 7, 4.5),
                             squeeze=False)
    ax = axes[0][0]
    for grid, g in doc["grids"].items():
        xs = [b["interactions_per_step"] for b in g["by_scale"]]
        line = ax.plot(xs, [b["ns_per_interaction_at_one_speed"] for b in g["by_scale"]], "o",
                       label=f"{grid} (measured)")[0]
        form = g["forms"].get("interactions+const", {})
        if form.get("identifiable"):
            c = form["coefficients"]
            lo, hi = min(xs), max(xs)
            grid_x = [lo * (hi / lo) ** (k / 50) for k in range(51)]
            ax.plot(grid_x, [c["ns_per_interaction"] + 1e3 * c["us_per_step"] / x for x in grid_x],
                    "-", color=line.get_color(),
                    label=f"{grid}: {c['ns_per_interaction']:.1f} ns + {c['us_per_step']:.0f} us/step")
    ax.set_xscale("log")
    ax.set_xlabel("interactions per step of the busiest rank")
    ax.set_ylabel("compute per interaction, ns (one host speed)")
    ax.set_title(f"Scale sweep: {doc['setup']}, {doc['ranks']} x {doc['threads']}"
                 + ("\n(runs to one Froude time: the fits read the memory order's rise too)"
                    if doc.get("froude_time_s") else ""), fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if orders:
        ax = axes[0][1]
        for grid, mo in orders.items():
            for b in mo["by_scale"]:
                ax.plot(mo["froude_time_s"], b["search_ns_per_interaction"], "o-",
                        label=f"{grid}, scale {b['scale']:g} "
                              f"(rise {b['search_rise_ns_per_interaction']:+.1f} ns)")
        ax.set_xlabel("Froude time (s)")
        ax.set_ylabel("search + id sort per interaction, ns (one host speed)")
        ax.set_title("The memory order's cost by scale")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    print(f"written {png}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grids", default="list,table,sorted", help="default list,table,sorted")
    ap.add_argument("--setup", default="dambreak", choices=["dambreak", "still", "column"],
                    help="default dambreak")
    ap.add_argument("--scales", default="0.25,0.35,0.5,0.7,1,1.4,2",
                    help="default 0.25,0.35,0.5,0.7,1,1.4,2")
    ap.add_argument("--ranks", type=int, default=2, help="default 2")
    ap.add_argument("--threads", type=int, default=1, help="default 1")
    ap.add_argument("--rounds", type=int, default=3, help="default 3")
    ap.add_argument("--steps", type=int, default=300, help="per run, default 300")
    ap.add_argument("--froude-time", type=float,
                    help="instead of --steps: every scale runs to this Froude time, in s "
                         "(sph --end-time T sqrt(scale)), for the memory order; default off")
    ap.add_argument("--interval", type=int, default=50, help="report interval, default 50")
    ap.add_argument("--fit-only", nargs="+", metavar="REPORT", help="fit these sph reports")
    ap.add_argument("--out", help="JSON output (default results/<host>/scale_sweep.json)")
    ap.add_argument("--png", help="plot (default: the JSON's path with .png)")
    args = ap.parse_args()
    try:
        if args.fit_only:
            reports = [(p, load_report(p, "sph", "an sph report")) for p in args.fit_only]
            first = reports[0][1]
            setup = first.get("config", {}).get("setup")
            ranks = first.get("config", {}).get("ranks")
            threads = first.get("config", {}).get("threads")
        else:
            grids = [g for g in args.grids.split(",") if g]
            bad = [g for g in grids if g not in ("list", "table", "sorted")]
            if bad or not grids:
                raise InputError(f"--grids '{args.grids}': expected list, table and/or sorted")
            scales = positive_list(args.scales, "scales")
            for name in ("ranks", "threads", "rounds", "steps", "interval"):
                if getattr(args, name) < 1:
                    raise InputError(f"--{name} {getattr(args, name)}: expected 1 or more")
            if args.froude_time is not None and not args.froude_time > 0:
                raise InputError(f"--froude-time {args.froude_time:g}: expected a time above 0 s")
            if args.froude_time is None and args.steps < 2 * args.interval:
                raise InputError(f"--steps {args.steps} with --interval {args.interval}: expected "
                                 f"at least two intervals (the first is dropped)")
            if len(set(scales)) < 2:
                raise InputError(f"--scales '{args.scales}': expected two or more scales")
            setup, ranks, threads = args.setup, args.ranks, args.threads
    except InputError as e:
        print(f"scale-sweep.py: {e}", file=sys.stderr)
        sys.exit(2)

    host = socket.gethostname()
    out = args.out or os.path.join(ROOT, "results", host, "scale_sweep.json")
    if not args.fit_only:
        reports = []
        with tempfile.TemporaryDirectory() as tmp:
            runs = list(itertools.product(grids, scales))
            total = args.rounds * len(runs)
            done = 0
            for k in range(args.rounds):
                # Rotating order: a drift of the host hits every grid and scale alike.
                order = runs[k % len(runs):] + runs[:k % len(runs)]
                for grid, scale in (order if k % 2 == 0 else order[::-1]):
                    path = os.path.join(tmp, f"{grid}_{scale:g}_{k}.json")
                    length = ("--steps", args.steps) if args.froude_time is None else \
                        ("--end-time", args.froude_time * scale ** 0.5)
                    run_sph(grid, setup, scale, ranks, threads, length, args.interval, path)
                    with open(path) as f:
                        reports.append((path, json.load(f)))
                    done += 1
                    print(f"scale-sweep: {done}/{total} done ({grid}, scale {scale:g}, round {k + 1})",
                          file=sys.stderr, flush=True)
    try:
        pts = [p for path, doc in reports for p in points_of(path, doc)]
        by_grid = {}
        for p in pts:
            by_grid.setdefault(p["grid"], []).append(p)
        for grid, g in by_grid.items():
            if len({p["scale"] for p in g}) < 2:
                raise InputError(f"grid {grid}: reports at one scale only; a sweep needs two or more")
    except InputError as e:
        print(f"scale-sweep.py: {e}", file=sys.stderr)
        sys.exit(2)
    first = reports[0][1]
    doc = {"benchmark": "scale-sweep", "schema": SCHEMA, "git_commit": git_commit(ROOT),
           "sph_git_commit": first.get("git_commit"), "host": first.get("host", host),
           "build": first.get("build"), "topology": first.get("topology"), "setup": setup,
           "ranks": ranks, "threads": threads, "reports": len(reports),
           "froude_time_s": None if args.fit_only else args.froude_time,
           "method": "per report interval after the first, the busiest rank's compute per step "
                     "(phase timers but comm, wait, output, rebalance) over its speed-gauge "
                     "factor, against its interactions and wall particles per step; weighted "
                     "least squares relative to each point's cost",
           "grids": {grid: fit(g) for grid, g in sorted(by_grid.items())}}
    write_json(out, doc)
    for grid, g in doc["grids"].items():
        print(f"{grid}:")
        for name, f in g["forms"].items():
            if not f["identifiable"]:
                print(f"  {name:20s} not identifiable from these scales")
                continue
            coef = ", ".join(f"{v:.3g} {k}" for k, v in f["coefficients"].items())
            res = " ".join(f"{s}:{100 * r:+.1f}%" for s, r in f["median_residual_by_scale"].items())
            print(f"  {name:20s} {coef}; rms {100 * f['relative_rms_residual']:.1f} %; "
                  f"median residual by scale {res}")
        mo = g.get("memory_order", {})
        if mo.get("by_scale"):
            t = mo["froude_time_s"]
            print(f"  memory order, Froude time {t[0]:.3f} -> {t[-1]:.3f} s (search, pair loops: "
                  f"ns per interaction; descents per interaction):")
            for b in mo["by_scale"]:
                srch, loops, d = (b["search_ns_per_interaction"], b["pair_loops_ns_per_interaction"],
                                  b["descents_per_interaction"])
                print(f"    scale {b['scale']:g}: search {srch[0]:.1f} -> {srch[-1]:.1f} "
                      f"(rise {b['search_rise_ns_per_interaction']:+.1f}), pair loops "
                      f"{loops[0]:.1f} -> {loops[-1]:.1f}, descents {d[0]:.3f} -> {d[-1]:.3f}")
    plot(doc, args.png or os.path.splitext(out)[0] + ".png")


if __name__ == "__main__":
    main()
