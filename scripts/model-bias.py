#!/usr/bin/python3
"""The model's bias over repeated main jobs: which configurations it gets wrong every time, and
which only as often as the host's run-to-run noise allows. One job cannot tell them apart (on a
noisy host a right prediction misses a single run by 10-30 %); several jobs can.

    /usr/bin/python3 scripts/model-bias.py VALIDATION.json VALIDATION.json [...] [--own-speed]
        [--min-jobs 3] [--json OUT]

Each file is a `sphmodel validate` report (a main job's validation.json; older jobs' are in the
git history of results/reference/<host>/). Per configuration (setup, grid, --overlap,
decomposition, scale, ranks x threads, steps) over the reports holding it: n, the mean of
e = ln(predicted / measured) shown as exp(mean) - 1, its standard deviation and standard error,
and t = mean / standard error. Marked systematic when |t| >= 2 over at least --min-jobs reports:
that error is the model's, not one run's. Below the table: the pooled standard deviation of e
about each configuration's mean (the noise the reports share) and the share of the mean square
of e that the configurations' means carry (the model's share; the rest is noise).
--own-speed: the errors at each run's own host speed (validate's speed_gauge.wall_error), a
diagnostic that takes the host's speed during the run out; reports without it are skipped.
--term: which error (default wall, the wall time): cost (the compute per interaction of the busy
rank-intervals within the cores, at each run's own speed: the median of validate's
cost_per_interaction), cost-first-third and cost-last-third (the same over the first and last
thirds of each run), or cost-trend (ln of the last third's over the first third's: how much more
the cost is predicted to rise through a run than it does; model/NOTES.md, session 73). The cost
terms are at each run's own speed already and are not given for time-shared runs. rank-compute:
each busy rank of the multi-rank runs apart (a row per rank), its compute at its own core's
speed (validate's per_rank error_at_own_speed, from session 77): how the model shares the cost
between the slabs, which the wall time and the pooled cost hide.
The targets against the expected error (--term wall): issue 6's targets (median |error| <= 5 %,
max <= 10 % over the validation set) applied to each configuration's mean error over its jobs
(those in at least --min-jobs reports) instead of one job's single runs: what the model gets
wrong every time, with the host's run-to-run noise averaged out. The max is given with its
configuration and with 2 standard errors added (a bound a mean of few jobs still allows), and
beside it the single jobs' figures (each report's median and max over its configurations): what
one main job shows. Neither replaces the other: a user runs one job.
--json OUT: the same as a JSON report (schema, this checkout's commit, each input's commit,
host, build and topology).
"""
import argparse
import math
import os
import statistics
import sys

from script_common import InputError, git_commit, load_report, write_json

SCHEMA = 1


def load_validation(path):
    doc = load_report(path, "sphmodel-validation", "a sphmodel validation report")
    if not isinstance(doc.get("configurations"), list):
        raise InputError(f"{path} has no configurations list")
    return doc


def configuration_key(c):
    grid = c["grid"] + (" overlap" if c.get("overlap") else "")
    if c.get("decomposition", "equal") != "equal":
        grid += " " + c["decomposition"]
    shared = " (shared)" if c.get("oversubscribed") else ""
    return (c["setup"], grid, f"{c['scale']:g}", f"{c['ranks']} x {c['threads']}{shared}",
            int(c["steps"]))


DEFAULT_MIN_JOBS = 3  # reports a configuration needs before it can be marked systematic
# Issue 6's targets on the total wall time over the validation set.
MEDIAN_TARGET = 0.05
MAX_TARGET = 0.10

TERMS = ("wall", "cost", "cost-first-third", "cost-last-third", "cost-trend", "rank-compute")


def cost_error_of(c, term):
    """ln(predicted / measured) of a configuration's cost per interaction (validate's
    cost_per_interaction), or None where validate gave none."""
    cp = c.get("cost_per_interaction")
    if not isinstance(cp, dict):
        return None
    if term == "cost":
        return math.log1p(cp["median_error"])
    first, last = cp.get("first_third"), cp.get("last_third")
    if term == "cost-first-third":
        return math.log1p(first["median_error"]) if first else None
    if term == "cost-last-third":
        return math.log1p(last["median_error"]) if last else None
    if not first or not last:
        return None
    return math.log1p(last["median_error"]) - math.log1p(first["median_error"])


def error_of(c, own_speed, path, term="wall"):
    """ln(predicted / measured) of one configuration, or None where --own-speed has no gauge."""
    try:
        if term != "wall":
            return cost_error_of(c, term)
        if own_speed:
            sg = c.get("speed_gauge")
            if not isinstance(sg, dict) or sg.get("wall_error") is None:
                return None
            return math.log1p(sg["wall_error"])
        return math.log1p(c["wall_error"])
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"{path}: a configuration without a usable {term} error ({e})")


def rank_errors_of(c, path):
    """(rank, ln(predicted / measured)) of each busy rank of a multi-rank configuration at its
    own core's speed (validate's phases.compute.per_rank[].error_at_own_speed, session 77);
    none from a report before it."""
    try:
        if c["ranks"] < 2:
            return []
        ranks = c["phases"]["compute"].get("per_rank") or []
        return [(r, math.log1p(x["error_at_own_speed"])) for r, x in enumerate(ranks)
                if x.get("busy") and x.get("error_at_own_speed") is not None]
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"{path}: a configuration without a usable per-rank compute ({e})")


def summarise(reports, own_speed, min_jobs, term="wall"):
    errors = {}
    per_report = []  # each report's |error| per configuration: the single jobs' figures
    for path, doc in reports:
        per_report.append([])
        for c in doc["configurations"]:
            try:
                key = configuration_key(c)
            except KeyError as e:
                raise InputError(f"{path}: a configuration without {e}")
            if term == "rank-compute":
                for r, e in rank_errors_of(c, path):
                    errors.setdefault(key[:3] + (f"{key[3]} rank {r}",) + key[4:], []).append(e)
                continue
            e = error_of(c, own_speed, path, term)
            if e is not None:
                errors.setdefault(key, []).append(e)
                per_report[-1].append(abs(math.expm1(e)))
    rows = []
    within_ss, within_dof, total_ss, total_n = 0.0, 0, 0.0, 0
    for key in sorted(errors):
        es = errors[key]
        n, mean = len(es), statistics.fmean(es)
        sd = statistics.stdev(es) if n >= 2 else None
        se = sd / math.sqrt(n) if sd else None
        t = mean / se if se else None
        rows.append({"setup": key[0], "grid": key[1], "scale": float(key[2]), "ranks_x_threads": key[3],
                     "steps": key[4], "jobs": n, "mean_error": math.expm1(mean),
                     "sd_log": sd, "se_log": se, "t": t,
                     "systematic": bool(t is not None and n >= min_jobs and abs(t) >= 2),
                     "errors": [math.expm1(e) for e in es]})
        within_ss += sum((e - mean) ** 2 for e in es)
        within_dof += n - 1
        total_ss += sum(e * e for e in es)
        total_n += n
    if within_dof < 1:
        raise InputError(f"no configuration has a {term} error in two reports: nothing to "
                         "separate bias from noise")
    out = {"configurations": rows,
           "noise_sd_log": math.sqrt(within_ss / within_dof),
           "bias_share_of_mean_square": 1 - within_ss / total_ss if total_ss > 0 else 0.0,
           "rms_error_log": math.sqrt(total_ss / total_n)}
    if term == "wall":
        out["targets_on_expected_error"] = targets_on_expected_error(rows, per_report, min_jobs)
    return out


def label_of(r):
    return f"{r['setup']} {r['grid']} s{r['scale']:g} {r['ranks_x_threads']}"


def targets_on_expected_error(rows, per_report, min_jobs):
    """Issue 6's targets on each configuration's mean error over its jobs, beside the same on
    each job's single runs (see the module's doc)."""
    held = [r for r in rows if r["jobs"] >= min_jobs]
    if not held:
        return None
    means = [abs(r["mean_error"]) for r in held]
    worst = max(held, key=lambda r: abs(r["mean_error"]))
    # |mean| + 2 standard errors of ln, as a relative error: the largest expected error the
    # jobs still allow for each configuration.
    upper = max(math.expm1(abs(math.log1p(r["mean_error"])) + 2 * (r["se_log"] or 0.0))
                for r in held)
    jobs = [(statistics.median(es), max(es)) for es in per_report if es]
    median, top = statistics.median(means), max(means)
    return {"configurations": len(held), "min_jobs": min_jobs,
            "median_target": MEDIAN_TARGET, "max_target": MAX_TARGET,
            "median_abs_mean_error": median, "median_met": median <= MEDIAN_TARGET,
            "max_abs_mean_error": top, "max_met": top <= MAX_TARGET,
            "max_configuration": label_of(worst),
            "max_abs_mean_error_plus_2_se": upper, "max_met_at_2_se": upper <= MAX_TARGET,
            "single_jobs": {"jobs": len(jobs),
                            "median_of_medians": statistics.median(j[0] for j in jobs),
                            "median_of_maxes": statistics.median(j[1] for j in jobs),
                            "both_met": sum(j[0] <= MEDIAN_TARGET and j[1] <= MAX_TARGET
                                            for j in jobs)}}


def pct(x):
    return "-" if x is None else f"{100 * x:+.1f} %"


def print_table(summary, reports, own_speed, min_jobs, term="wall"):
    what = {"wall": "Wall-time error " + ("at each run's own host speed" if own_speed
                                          else "as predicted"),
            "cost": "Cost per interaction error (busy rank-intervals within the cores, at each "
                    "run's own speed)",
            "cost-first-third": "Cost per interaction error over each run's first third",
            "cost-last-third": "Cost per interaction error over each run's last third",
            "cost-trend": "Cost per interaction error, last third over first third of each run",
            "rank-compute": "Compute error of each busy rank of the multi-rank runs at its own "
                            "core's speed (its own gauge; on a shared core a sample may hold the "
                            "other rank's turn)"}[term]
    print(f"{what} over {len(reports)} validation reports "
          f"(mean of ln(predicted / measured), shown as a percentage; systematic: |t| >= 2 over "
          f">= {min_jobs} reports)")
    print()
    print("| setup | grid | scale | ranks x threads | steps | jobs | mean error | sd | t | |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in summary["configurations"]:
        sd = "-" if r["sd_log"] is None else f"{100 * r['sd_log']:.1f} %"
        t = "-" if r["t"] is None else f"{r['t']:+.1f}"
        print(f"| {r['setup']} | {r['grid']} | {r['scale']:g} | {r['ranks_x_threads']} | {r['steps']} | "
              f"{r['jobs']} | {pct(r['mean_error'])} | {sd} | {t} | "
              f"{'**systematic**' if r['systematic'] else ''} |")
    print()
    print(f"Run-to-run noise (pooled sd of ln about each configuration's mean): "
          f"{100 * summary['noise_sd_log']:.1f} %; rms error {100 * summary['rms_error_log']:.1f} %, "
          f"of whose mean square the configurations' means carry "
          f"{100 * summary['bias_share_of_mean_square']:.0f} %.")
    n_sys = sum(r["systematic"] for r in summary["configurations"])
    print(f"Systematic: {n_sys} of {len(summary['configurations'])} configurations.")
    t = summary.get("targets_on_expected_error")
    if t:
        met = lambda ok: "met" if ok else "**missed**"
        sj = t["single_jobs"]
        print()
        print(f"The targets against the expected error (each configuration's mean over its jobs, "
              f"{t['configurations']} configurations in >= {t['min_jobs']} reports): median "
              f"|mean error| {100 * t['median_abs_mean_error']:.1f} % (target "
              f"{100 * t['median_target']:g} %: {met(t['median_met'])}), max "
              f"{100 * t['max_abs_mean_error']:.1f} % ({t['max_configuration']}; target "
              f"{100 * t['max_target']:g} %: {met(t['max_met'])}), "
              f"{100 * t['max_abs_mean_error_plus_2_se']:.1f} % with 2 standard errors added "
              f"({met(t['max_met_at_2_se'])}). The single jobs: median of their medians "
              f"{100 * sj['median_of_medians']:.1f} %, of their maxes "
              f"{100 * sj['median_of_maxes']:.1f} %; both targets met in {sj['both_met']} of "
              f"{sj['jobs']}.")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reports", nargs="+", help="sphmodel validation reports (validation.json)")
    ap.add_argument("--own-speed", action="store_true",
                    help="the errors at each run's own host speed (default: as predicted)")
    ap.add_argument("--term", default="wall",
                    help="which error: wall (default), cost, cost-first-third, cost-last-third, "
                         "cost-trend or rank-compute (see above)")
    ap.add_argument("--min-jobs", type=int, default=DEFAULT_MIN_JOBS,
                    help="reports a configuration needs before it can be marked systematic (default 3)")
    ap.add_argument("--json", metavar="OUT", help="also write the summary as JSON to OUT")
    args = ap.parse_args()
    try:
        if args.min_jobs < 2:
            raise InputError(f"--min-jobs {args.min_jobs}: expected an integer of 2 or more")
        if args.term not in TERMS:
            raise InputError(f"--term {args.term!r}: expected one of {', '.join(TERMS)}")
        if args.own_speed and args.term != "wall":
            raise InputError(f"--own-speed with --term {args.term}: the cost and rank terms are "
                             "at each run's own speed already; --own-speed applies to --term wall")
        if len(args.reports) < 2:
            raise InputError(f"{len(args.reports)} validation report given: expected 2 or more "
                             f"(one job cannot tell bias from noise)")
        reports = [(p, load_validation(p)) for p in args.reports]
        summary = summarise(reports, args.own_speed, args.min_jobs, args.term)
    except InputError as e:
        print(f"model-bias.py: {e}", file=sys.stderr)
        sys.exit(2)
    print_table(summary, reports, args.own_speed, args.min_jobs, args.term)
    if args.json:
        write_json(args.json, report_json(summary, reports, args.own_speed, args.term, args.min_jobs))


def report_json(summary, reports, own_speed, term, min_jobs):
    """The summary as a JSON report: schema, this checkout's commit, each input's provenance."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    doc = {"schema": SCHEMA, "benchmark": "sphperf-model-bias", "git_commit": git_commit(root),
           "errors": "own_speed" if own_speed else "as_predicted", "term": term,
           "min_jobs": min_jobs,
           "inputs": [{"path": p, "git_commit": d.get("git_commit"), "host": d.get("host"),
                       "timestamp": d.get("timestamp"), "build": d.get("build"),
                       "topology": d.get("topology")} for p, d in reports]}
    doc.update(summary)
    return doc


if __name__ == "__main__":
    main()
