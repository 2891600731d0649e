#!/usr/bin/python3
"""Does this host's speed depend on how long a run has been going? The speed gauge of sph
reports (a fixed piece of work timed every few steps, sph --speed-gauge-every) split into what
changes within a run and what differs between runs of different lengths.

    /usr/bin/python3 scripts/gauge-drift.py REPORT|DIR [...] [--max-rank 1]
        [--edges 0,0.25,0.5,1,2,4,8,16] [--json OUT]

Each argument is an sph report or a folder of them (every *.json in it that is an sph report;
a main job's results/<host>/runs and repeats). Each busy rank-interval of ranks 0..--max-rank
(default 1: within this machine's two cores) gives ln(gauge CPU seconds per sample), weighted by
its compute, at the time since the run started (the middle of the interval, rank 0's timers
summed). Within runs: ln gauge = the run's level + f(time bin), fitted by weighted least squares
(alternating projections) with f = 0 in the first bin; shown as exp(f) - 1, the gauge reading
relative to a run's start (negative: the host faster later in a run), with a standard error
from a 10-group jackknife over the runs. Between runs: the slope of ln(the run's whole gauge)
on ln(its wall time), with its standard error: whether longer runs meet a faster host, which a
model calibrated on short runs would miss. model/NOTES.md, session 79, has what it found here.
--json OUT: the same as a JSON report (schema, this checkout's commit; the inputs' hosts, and
each distinct build and topology among them).
"""
import argparse
import glob
import math
import os
import sys

from script_common import InputError, git_commit, load_report, write_json

SCHEMA = 1
JACKKNIFE_GROUPS = 10


def edges_of(text):
    try:
        edges = [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"--edges '{text}': expected increasing seconds, e.g. 0,0.5,1,2")
    if len(edges) < 2 or edges[0] != 0 or any(b <= a for a, b in zip(edges, edges[1:])):
        raise InputError(f"--edges '{text}': expected at least two increasing seconds from 0")
    return edges


def report_paths(args):
    """(path, named): a folder's JSON files (not named: other kinds are skipped) or a file."""
    paths = []
    for a in args:
        if os.path.isdir(a):
            paths += [(p, False) for p in sorted(glob.glob(os.path.join(a, "*.json")))]
        elif os.path.isfile(a):
            paths.append((a, True))
        else:
            raise InputError(f"{a}: no such file or folder")
    return paths


def load_run(path, max_rank, named):
    """(points, wall_s, gauge_s_per_sample, host) of an sph report; None for another kind of
    JSON in a folder; InputError for a named file that is not an sph report."""
    try:
        doc = load_report(path, "sph", "an sph report")
    except InputError:
        if named:
            raise
        return None  # another kind of file in a folder
    try:
        points, t, cpu, samples = [], 0.0, 0.0, 0.0
        for iv in doc["intervals"]:
            ranks = iv["ranks"]
            wall = sum(ranks[0]["timers"].values())
            middle = t + wall / 2
            t += wall
            for rk in ranks[: max_rank + 1]:
                n, compute = rk["gauge_samples"], rk["timers"]["comp_s"]
                if n > 0 and rk["gauge_cpu_s"] > 0 and compute > 0:
                    points.append((middle, math.log(rk["gauge_cpu_s"] / n), compute))
                    cpu += rk["gauge_cpu_s"]
                    samples += n
        wall_s = float(doc["wall_s"])
    except (KeyError, TypeError, IndexError) as e:
        raise InputError(f"{path}: an sph report without intervals' ranks, timers and gauge "
                         f"samples (missing {e})")
    source = {"host": doc.get("host"), "build": doc.get("build"), "topology": doc.get("topology")}
    return points, wall_s, (cpu / samples if samples else 0.0), source


def bin_of(t, edges):
    for b in range(len(edges) - 1):
        if t < edges[b + 1]:
            return b
    return len(edges) - 2  # the last bin is open-ended


def fit_within(runs, nbins, iterations=200):
    """ln g = a_run + f_bin, weighted least squares with f_0 = 0: the bins' f (None where no
    run has a point)."""
    f = [0.0] * nbins
    seen = [False] * nbins
    for pts in runs:
        for b, _, _ in pts:
            seen[b] = True
    for _ in range(iterations):
        levels = [sum(w * (y - f[b]) for b, y, w in pts) / sum(w for _, _, w in pts)
                  for pts in runs]
        num, den = [0.0] * nbins, [0.0] * nbins
        for a, pts in zip(levels, runs):
            for b, y, w in pts:
                num[b] += w * (y - a)
                den[b] += w
        new = [num[b] / den[b] if den[b] > 0 else 0.0 for b in range(nbins)]
        first = next((new[b] for b in range(nbins) if seen[b]), 0.0)
        new = [x - first for x in new]
        done = max(abs(x - y) for x, y in zip(new, f)) < 1e-12
        f = new
        if done:
            break
    return [f[b] if seen[b] else None for b in range(nbins)]


def within_runs(runs, edges):
    nbins = len(edges) - 1
    binned = [[(bin_of(t, edges), y, w) for t, y, w in pts] for pts in runs]
    binned = [pts for pts in binned if len({b for b, _, _ in pts}) > 1]  # a run in one bin says nothing
    f = fit_within(binned, nbins)
    groups = min(JACKKNIFE_GROUPS, len(binned))
    jack = [fit_within([p for i, p in enumerate(binned) if i % groups != g], nbins)
            for g in range(groups)] if groups > 1 else []
    rows = []
    for b in range(nbins):
        runs_b = sum(1 for pts in binned if any(x == b for x, _, _ in pts))
        se = None
        vals = [j[b] for j in jack if j[b] is not None]
        if f[b] is not None and len(vals) == groups and groups > 1:
            mean = sum(vals) / groups
            se = math.sqrt((groups - 1) / groups * sum((v - mean) ** 2 for v in vals))
        rows.append({"from_s": edges[b], "to_s": edges[b + 1] if b + 1 < nbins else None,
                     "runs": runs_b,
                     "gauge_change": math.exp(f[b]) - 1 if f[b] is not None else None,
                     "ln_se": se})
    return rows, len(binned)


def between_runs(whole):
    """Slope of ln(run gauge) on ln(run wall time), with its standard error."""
    pts = [(math.log(w), math.log(g)) for w, g in whole if w > 0 and g > 0]
    n = len(pts)
    if n < 3:
        return {"runs": n, "slope": None, "slope_se": None}
    mx = sum(x for x, _ in pts) / n
    my = sum(y for _, y in pts) / n
    sxx = sum((x - mx) ** 2 for x, _ in pts)
    if sxx == 0:
        return {"runs": n, "slope": None, "slope_se": None}
    slope = sum((x - mx) * (y - my) for x, y in pts) / sxx
    resid = sum((y - my - slope * (x - mx)) ** 2 for x, y in pts)
    return {"runs": n, "slope": slope, "slope_se": math.sqrt(resid / (n - 2) / sxx)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("inputs", nargs="+", help="sph reports or folders of them")
    ap.add_argument("--max-rank", type=int, default=1,
                    help="the highest rank read (default 1: ranks 0 and 1)")
    ap.add_argument("--edges", default="0,0.25,0.5,1,2,4,8,16",
                    help="time-bin edges in seconds since the run started, from 0 (default "
                         "0,0.25,0.5,1,2,4,8,16; the last bin is open)")
    ap.add_argument("--json", help="also write the result as a JSON report")
    a = ap.parse_args()
    try:
        if a.max_rank < 0:
            raise InputError(f"--max-rank {a.max_rank}: expected 0 or more")
        edges = edges_of(a.edges)
        runs, whole, sources = [], [], []
        for p, named in report_paths(a.inputs):
            run = load_run(p, a.max_rank, named)
            if run is None or not run[0]:
                continue
            points, wall_s, gauge, source = run
            runs.append(points)
            whole.append((wall_s, gauge))
            if source not in sources:
                sources.append(source)
        if not runs:
            raise InputError("no sph report with speed-gauge samples among the inputs")
    except InputError as e:
        print(f"gauge-drift.py: {e}", file=sys.stderr)
        sys.exit(2)
    rows, used = within_runs(runs, edges)
    between = between_runs(whole)
    print(f"{len(runs)} runs; within runs ({used} spanning two bins or more), the gauge "
          "against the run's first bin (negative: the host faster later in a run):")
    print("| time since start | runs | gauge change | standard error |")
    print("|---|---|---|---|")
    for r in rows:
        span = f"{r['from_s']:g}-{r['to_s']:g} s" if r["to_s"] is not None else \
            f"{r['from_s']:g} s on"
        change = "-" if r["gauge_change"] is None else f"{100 * r['gauge_change']:+.1f} %"
        se = "-" if r["ln_se"] is None else f"{100 * r['ln_se']:.1f} %"
        print(f"| {span} | {r['runs']} | {change} | {se} |")
    if between["slope"] is not None:
        print(f"Between runs: ln(run gauge) = {between['slope']:+.4f} (se "
              f"{between['slope_se']:.4f}) x ln(run wall time) + c over {between['runs']} runs "
              "(negative: longer runs meet a faster host)")
    if a.json:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        write_json(a.json, {"schema": SCHEMA, "benchmark": "sphperf-gauge-drift",
                            "git_commit": git_commit(root), "inputs": sources,
                            "max_rank": a.max_rank, "edges_s": edges, "runs": len(runs),
                            "within_runs": {"runs_spanning_bins": used, "bins": rows},
                            "between_runs": between})


if __name__ == "__main__":
    main()
