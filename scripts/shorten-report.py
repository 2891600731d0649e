#!/usr/bin/env python3
"""An SPH report cut to its first steps: what a shorter run of the same configuration would have
reported, from the longer run (scripts/replay-job.sh --shorten).

    scripts/shorten-report.py --fraction F IN.json OUT.json

Keeps the first round(F x intervals) intervals (at least one), sets config.steps to the last kept
interval's step, and scales wall_s by the kept share of the run's time: per interval the longest
rank's phase timers (every step ends in an exchange, so the slowest rank sets the step), summed.
The physics is deterministic, so the kept intervals are exactly a shorter run's counts, and their
times those the run paid then; only the set-up before the first step, a few ms, is not in the
timers and is scaled with them. totals (min/avg/max over ranks of each timer summed over the kept
intervals) and the rates are recomputed; the report records `shortened` (the original steps,
wall_s and the fraction). Exit 2 with one line on bad input; OUT is written only when complete.
"""
import argparse
import json
import os
import sys
import tempfile


def fail(msg):
    print(f"shorten-report.py: {msg}", file=sys.stderr)
    sys.exit(2)


def fraction(text):
    try:
        f = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number (expected 0 < F <= 1)")
    if not 0 < f <= 1:
        raise argparse.ArgumentTypeError(f"{text} is outside 0 < F <= 1")
    return f


def longest(interval):
    return max(sum(r["timers"].values()) for r in interval["ranks"])


def shorten(report, frac):
    if report.get("benchmark") != "sph":
        raise ValueError(f"benchmark is '{report.get('benchmark')}', expected an sph report")
    if "restart" in report:
        raise ValueError("continues a checkpoint (sph --restart): cut the uninterrupted run")
    intervals = report["intervals"]
    if not intervals:
        raise ValueError("no intervals recorded")
    keep = max(1, int(round(len(intervals) * frac)))
    total = sum(longest(iv) for iv in intervals)
    kept = sum(longest(iv) for iv in intervals[:keep])
    if total <= 0:
        raise ValueError("its intervals record no time")
    share = kept / total
    old_steps, old_wall = report["config"]["steps"], report["wall_s"]
    steps = intervals[keep - 1]["step"]
    report["intervals"] = intervals[:keep]
    report["config"]["steps"] = steps
    report["wall_s"] = old_wall * share
    # Rates per second of the run: the counts kept over the time kept.
    work = steps / old_steps
    for key in ("steps_per_s", "particle_steps_per_s"):
        if key in report:
            report[key] *= work / share
    if "neighbour_interactions_per_s" in report:
        per_iv = lambda ivs: sum(r["interactions"] for iv in ivs for r in iv["ranks"])
        whole = per_iv(intervals)
        if whole > 0:
            report["neighbour_interactions_per_s"] *= per_iv(intervals[:keep]) / whole / share
    if "decomposition" in report:
        report["decomposition"]["rebalances"] = [
            b for b in report["decomposition"].get("rebalances", []) if b.get("step", 0) <= steps
        ]
    ranks = len(report["intervals"][0]["ranks"])
    names = sorted({k for iv in report["intervals"] for r in iv["ranks"] for k in r["timers"]})
    def over_ranks(values):
        return {"min": min(values), "avg": sum(values) / len(values), "max": max(values)}
    report["totals"] = {
        "timers": {
            k: over_ranks([sum(iv["ranks"][i]["timers"].get(k, 0.0) for iv in report["intervals"])
                           for i in range(ranks)])
            for k in names
        },
        "idle_s": over_ranks([sum(iv["ranks"][i].get("idle_s", 0.0) for iv in report["intervals"])
                              for i in range(ranks)]),
    }
    report["shortened"] = {"fraction": frac, "from_steps": old_steps, "from_wall_s": old_wall}
    return report


class Parser(argparse.ArgumentParser):
    # One line on bad options, as every sphperf tool: argparse would print its usage first.
    def error(self, message):
        fail(message)


def main():
    p = Parser(description=__doc__.split("\n\n")[0])
    p.add_argument("--fraction", type=fraction, required=True,
                   help="share of the run's intervals to keep, 0 < F <= 1 (no default)")
    p.add_argument("input", help="an sph report (sph --report)")
    p.add_argument("output", help="the shortened report")
    a = p.parse_args()
    try:
        with open(a.input) as f:
            report = json.load(f)
    except OSError as e:
        fail(f"'{a.input}': {e.strerror}")
    except json.JSONDecodeError as e:
        fail(f"'{a.input}': not JSON ({e.msg} at line {e.lineno})")
    try:
        report = shorten(report, a.fraction)
    except (KeyError, TypeError, ValueError) as e:
        what = f"missing key {e}" if isinstance(e, KeyError) else str(e)
        fail(f"'{a.input}': {what}")
    folder = os.path.dirname(os.path.abspath(a.output))
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".part")
    with os.fdopen(fd, "w") as f:
        json.dump(report, f, indent=1)
    os.replace(tmp, a.output)


if __name__ == "__main__":
    main()
