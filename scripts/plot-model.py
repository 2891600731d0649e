#!/usr/bin/env python3
"""Plots and validation.md of the SPH runtime model, from the JSON files in one results folder.

    python3 scripts/plot-model.py --dir results/<host> [--calibration-s S --validation-s S]

Reads model.json, prediction_*.json, validation.json and runs/*.json; writes roofline.png,
scaling.png, workload.png, regressions.png, comm_error.png and validation.md beside them.
"""
import argparse
import datetime
import glob
import json
import os
import re
import statistics
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402


def load(path):
    with open(path) as f:
        return json.load(f)


def roofline(model, out):
    rl = model["roofline"]
    c = rl["ceilings"]
    fig, ax = plt.subplots(figsize=(10, 5))
    xs = [2 ** (k / 4) for k in range(-40, 33)]
    ax.loglog(xs, [min(c["peak_gflops"], c["stream_triad_GBps"] * x) for x in xs], "k-",
              label=f"peak {c['peak_gflops']:.0f} GFLOP/s (FMA probe), triad {c['stream_triad_GBps']:.0f} GB/s")
    ax.axhline(c["dgemm_gflops"], color="gray", ls="--", label=f"DGEMM {c['dgemm_gflops']:.0f} GFLOP/s")
    ax.axhline(c["peak_gflops_per_core"], color="gray", ls=":", label="peak of one core")
    oi = rl["operational_intensity_flop_per_byte"]
    ax.axvline(oi, color="tab:red", ls="--", lw=1,
               label=f"SPH kernel, no-reuse intensity {oi:.2f} flop/B")
    ax.axvline(89 / 56, color="tab:purple", ls=":", lw=1, label="thesis 89/56 flop/B")
    sorted_oi = rl.get("schemes", {}).get("sorted", {}).get("operational_intensity_flop_per_byte")
    if sorted_oi:
        ax.axvline(sorted_oi, color="tab:green", ls="--", lw=1,
                   label=f"Cell+Sorted, in-range candidates packed: {sorted_oi:.2f} flop/B")
    for p in rl["runs"]:
        ax.plot(p.get("operational_intensity_flop_per_byte", oi), p["achieved_gflops"], "o", ms=6,
                label=f"{p['grid']} {p['ranks']}x{p['threads']}: {p['achieved_gflops']:.2f} GFLOP/s")
    ax.set_xlabel("operational intensity (flop/byte)")
    ax.set_ylabel("GFLOP/s")
    ax.set_title("Roofline: ceilings of this node and the SPH kernel (calibration runs)")
    # Outside the axes: one entry per calibration run (28 in the main job) would hide the ceilings;
    # in two columns past 20 entries, so that none runs off the figure.
    entries = len(ax.get_legend_handles_labels()[0])
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              ncol=2 if entries > 20 else 1)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def scaling(predictions, validation, out):
    fig, axes = plt.subplots(1, 3, figsize=(16, 4))
    measured = {}
    for r in validation["configurations"]:
        measured[(r["setup"], r["grid"], r["scale"], r["ranks"], r["threads"],
                  r.get("decomposition", "equal"), r.get("overlap", False))] = r["measured_wall_s"]
    for p in predictions:
        q = p["request"]
        dec = p["configurations"][0].get("decomposition", "equal")
        overlap = q.get("overlap", False)
        key = (f"{q['setup']} s{q['scale']:g} {q['grid']}" + ("" if dec == "equal" else f" {dec}")
               + (" overlap" if overlap else "")
               + ("" if q["threads"] == 1 else f" x{q['threads']} threads"))
        ranks = [c["ranks"] for c in p["configurations"]]
        wall = [c["wall_s"] for c in p["configurations"]]
        # A single rank count is a marker, not an invisible one-point line.
        line, = axes[0].plot(ranks, wall, "-" if len(ranks) > 1 else "x", label=f"{key} predicted")
        # The prediction's band (+-2 sd of the calibration runs' scatter, session 44).
        bands = [c.get("wall_band") for c in p["configurations"]]
        if all(bands):
            lo = [b["low_s"] for b in bands]
            hi = [b["high_s"] for b in bands]
            if len(ranks) > 1:
                axes[0].fill_between(ranks, lo, hi, color=line.get_color(), alpha=0.12, linewidth=0)
            else:
                axes[0].errorbar(ranks, wall, yerr=[[w - l for w, l in zip(wall, lo)],
                                                    [h - w for w, h in zip(wall, hi)]],
                                 fmt="none", color=line.get_color(), alpha=0.5, capsize=3)
        mr = [(c["ranks"], measured.get((q["setup"], q["grid"], q["scale"], c["ranks"],
                                         q["threads"], dec, overlap)))
              for c in p["configurations"]]
        mr = [(r, w) for r, w in mr if w is not None]
        if mr:
            axes[0].plot([r for r, _ in mr], [w for _, w in mr], "o", color=line.get_color(),
                         label=f"{key} measured")
        base = wall[0] * ranks[0]
        axes[1].plot(ranks, [base / ranks[0] / w for w in wall], "-", color=line.get_color())
        axes[2].plot(ranks, [base / (r * w) for r, w in zip(ranks, wall)], "-", color=line.get_color())
        if mr:
            mb = mr[0][1] * mr[0][0] if mr[0][0] == ranks[0] else None
            if mb:
                axes[1].plot([r for r, _ in mr], [mb / ranks[0] / w for _, w in mr], "o", color=line.get_color())
                axes[2].plot([r for r, _ in mr], [mb / (r * w) for r, w in mr], "o", color=line.get_color())
    axes[0].set_ylabel("wall time (s)")
    axes[1].set_ylabel("speed-up vs fewest ranks")
    axes[2].set_ylabel("parallel efficiency")
    for ax in axes:
        ax.set_xlabel("ranks")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
    # The long caveat once for the three panels: per panel it ran into its neighbours.
    cores = validation.get("topology", {}).get("cores")
    if cores:
        fig.supxlabel(f"1 thread per rank unless marked; above {cores} ranks they share the {cores} cores",
                      fontsize=9)
    # One legend, outside the panels, so that it hides no point.
    handles, labels = axes[0].get_legend_handles_labels()
    axes[2].legend(handles, labels, fontsize=6, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("Predicted (lines; shaded: +-2 sd of the calibration runs' scatter) and measured (dots) "
                 "wall time, speed-up, efficiency (thesis Fig. 4.9)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def rank_compute_ms(intervals, r, measured):
    """Compute per step (ms) of rank r in each interval: a prediction's, or a report's timers
    without comm, wait and output (the model's compute)."""
    out, prev = [], 0
    for iv in intervals:
        rank = iv["ranks"][r]
        if measured:
            c = sum(v for k, v in rank["timers"].items() if k not in ("comm_s", "wait_s", "output_s"))
            out.append(1e3 * c / max(rank["steps"], 1))
        else:
            out.append(1e3 * rank["compute_s"] / max(iv["step"] - prev, 1))
            prev = iv["step"]
    return out


def workload(model, predictions, runs_dir, out):
    pred = next((p for p in predictions if p["request"]["setup"] == "dambreak"
                 and p["request"]["scale"] == 1 and p["request"]["grid"] == "table"
                 and p["configurations"][0].get("decomposition", "equal") == "equal"), None)
    if pred is None:
        return
    cfg = max(pred["configurations"], key=lambda c: c["ranks"])
    P = cfg["ranks"]
    run = os.path.join(runs_dir, f"val_dambreak_s1_table_r{P}.json")
    m = load(run) if os.path.exists(run) else None
    # The same prediction with every rank at the whole run's memory order (session 56's
    # comparison), where the job made it.
    flat_path = os.path.join(os.path.dirname(out), "one-order-per-run", "prediction_dambreak_s1_table.json")
    flat = None
    if os.path.exists(flat_path):
        flat = next((c for c in load(flat_path)["configurations"] if c["ranks"] == P
                     and c.get("decomposition", "equal") == "equal"), None)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    t = [iv["time_s"] for iv in cfg["intervals"]]
    for r in range(P):
        line, = axes[0].plot(t, [iv["ranks"][r]["field"] for iv in cfg["intervals"]], "-",
                             label=f"rank {r} predicted")
        c = line.get_color()
        busy = any(iv["ranks"][r]["interactions"] > 0 for iv in cfg["intervals"])
        if busy:
            axes[1].plot(t, rank_compute_ms(cfg["intervals"], r, False), "-", color=c,
                         label=f"rank {r} predicted, its columns' memory order")
            if flat is not None:
                axes[1].plot(t, rank_compute_ms(flat["intervals"], r, False), ":", color=c,
                             label=f"rank {r} predicted, the whole run's order")
        if m is not None:
            mt = [iv["time_s"] for iv in m["intervals"]]
            axes[0].plot(mt, [iv["ranks"][r]["field_mean"] for iv in m["intervals"]], "o", ms=3,
                         color=c, label=f"rank {r} measured")
            if busy:
                axes[1].plot(mt, rank_compute_ms(m["intervals"], r, True), "o", ms=3, color=c,
                             label=f"rank {r} measured")
    for ax in axes:
        ax.set_xlabel("simulated time (s)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("field particles owned")
    axes[1].set_ylabel("compute per step (ms)")
    trace = model.get("traces", {}).get("dambreak", {})
    source = f"a scale-{trace['scale']:g} trace" if "scale" in trace else "the calibration's trace"
    axes[0].set_title(f"Workload per rank, dam break scale 1, {P} ranks (thesis Fig. 4.3)\n"
                      f"predicted from {source} by Froude similarity", fontsize=10)
    axes[1].set_title("Compute per rank, the same run: each rank at its own columns'\n"
                      "memory order (model/README.md) against the whole run's", fontsize=10)
    axes[0].legend(fontsize=7, ncol=2)
    axes[1].legend(fontsize=6, ncol=1)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def regressions(model, runs_dir, out):
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.3))
    for ax, key, label in ((axes[0], "pairs", "pairs"), (axes[1], "exported", "exports")):
        xs, ys = [], []
        for path in sorted(glob.glob(os.path.join(runs_dir, "cal_*.json"))):
            for iv in load(path)["intervals"]:
                for r in iv["ranks"]:
                    if r["field_mean"] > 0:
                        xs.append(r["field_mean"])
                        ys.append(r[key])
        ax.plot(xs, ys, ".", ms=3, label="calibration rank-intervals")
        hi = max(xs) if xs else 1
        for setup, laws in model["regressions"].items():
            if setup == "thesis":
                continue
            reg = laws[label]["coefficients"]
            m, r = reg["m"]["value"], reg["r"]["value"]
            ax.plot([0, hi], [r, m * hi + r], "-" if setup != "pooled" else ":",
                    label=f"{setup}: m={m:.4g}, r={r:.4g}, R²={laws[label]['r2']:.3f}")
        t = model["regressions"]["thesis"][label]
        ax.plot([0, hi], [t["r"], t["m"] * hi + t["r"]], "k--", label=f"thesis m={t['m']}, r={t['r']}")
        ax.set_xlabel("field particles of the rank, n")
        ax.set_ylabel(f"{label} per step")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle("p(n) = m n + r (thesis Eq. 4.3, Fig. 4.12)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def comm_error(validation, out):
    fig, ax = plt.subplots(figsize=(13, 5))
    for r in validation["configurations"]:
        s = r["comm_series"]
        if r["ranks"] < 2 or not s:
            continue
        name = (f"{r['setup']} s{r['scale']:g} {r['grid']}"
                + (" balanced" if r.get("decomposition") == "balanced" else "")
                + (" overlap" if r.get("overlap") else "") + f" {r['ranks']}r")
        line, = ax.plot([e["time_s"] for e in s], [100 * e["model_error"] for e in s], "-", label=f"{name} model")
        if "inline_error" in s[0]:
            ax.plot([e["time_s"] for e in s], [100 * e.get("inline_error", 0) for e in s], ":",
                    color=line.get_color(), label=f"{name} inline")
        if "inline_hockney_error" in s[0]:
            ax.plot([e["time_s"] for e in s], [100 * e.get("inline_hockney_error", 0) for e in s],
                    "x", ms=3, color=line.get_color(), label=f"{name} ping-pong Hockney")
    ax.axhline(0, color="k", lw=0.8)
    ax.axhspan(-20, 20, color="green", alpha=0.08, label="±20 % target")
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("communication prediction error (%)")
    ax.set_yscale("symlog", linthresh=100)
    ax.set_title("Communication prediction error per interval (thesis Fig. 4.11)")
    # Outside the axes: with a dozen configurations a legend inside hides the lines.
    ax.legend(fontsize=6, ncol=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def repeated_runs(folder, kind):
    """'name w1, w2, w3 s (started 0, +t2, +t3 s)' for each run of kind 'val' or 'cal' repeated
    by model-node.sh (repeats/): since session 42 the runs are spread over the job."""
    runs = {}
    for path in sorted(glob.glob(os.path.join(folder, "repeats", f"{kind}_*.rep*.json"))):
        name, k = os.path.basename(path)[:-len(".json")].rsplit(".rep", 1)
        r = load(path)
        start = datetime.datetime.fromisoformat(r["timestamp"].replace("Z", "+00:00"))
        runs.setdefault(name, []).append((int(k), r["wall_s"], start))
    out = []
    for name, v in runs.items():
        v.sort()
        t0 = v[0][2]
        out.append(f"{name[len(kind) + 1:]} " + ", ".join(f"{w:.2f}" for _, w, _ in v) + " s (started "
                   + ", ".join(f"{(t - t0).total_seconds():+.0f}" for _, _, t in v) + " s)")
    return out


def fresh_source(args):
    """Which exchange figures costed the validation runs' shifts inline."""
    reports = [load(p) for p in sorted(glob.glob(os.path.join(args.dir, "runs", "val_*.json")))]
    fresh = sum(1 for r in reports if r.get("exchange_report"))
    multi = sum(1 for r in reports if len(r.get("placement_pus", [])) > 1)
    if not fresh:
        return "figures from the machine profile"
    took = f", {args.fresh_exchange_s:.0f} s in all" if args.fresh_exchange_s else ""
    # A blocking run and its --overlap twin right after it share one (model-node.sh --twin).
    names = [r["exchange_report"] for r in reports if r.get("exchange_report")]
    shared = sum(1 for n in set(names) if names.count(n) > 1)
    twins = (f", the --overlap twin of a blocking run reusing that run's ({shared} pair"
             f"{'s' if shared != 1 else ''})" if shared else "")
    return (f"an exchange benchmark on the run's rank count right before each validation run within "
            f"the cores{twins}, {fresh} of the {multi} multi-rank runs (sph --exchange{took}); the "
            f"others the machine profile's")


def inline_by_load(validation, key="inline_error"):
    """The per-interval inline error within the cores and time-shared apart."""
    within, shared = [], []
    for c in validation["configurations"]:
        e = [abs(x[key]) for x in c["comm_series"] if key in x]
        (shared if c["oversubscribed"] else within).extend(e)
    part = lambda v: (f"median {100 * statistics.median(v):.1f} % over {len(v)} intervals" if v
                      else "no interval")
    return f"within the cores {part(within)}, time-shared {part(shared)}"


def inline_by_exchange(validation):
    """The per-interval inline error of each exchange apart, within the cores: the signed median
    says which way each is off (they may cancel in the sum), the absolute one how far."""
    errors = {}
    for c in validation["configurations"]:
        if c["oversubscribed"]:
            continue
        for x in c["comm_series"]:
            for kind, e in x.get("shifts", {}).items():
                errors.setdefault(kind, []).append(e["inline_error"])
    parts = [f"{kind} {100 * statistics.median(errors[kind]):+.1f} % signed, "
             f"{100 * statistics.median([abs(v) for v in errors[kind]]):.1f} % absolute"
             for kind in ("migration", "ghosts", "densities") if errors.get(kind)]
    if not parts:
        return ""
    return (f"By exchange (inline, within the cores, per interval, median): {'; '.join(parts)} "
            f"(over {len(errors.get('ghosts', []))} intervals).")


def exchange_drift(folder, model):
    """The spread of the exchange benchmarks run through the job at the 2-rank points the app's
    shifts use most: how far a profile measured once may be from any one run."""
    point = lambda rep, gap_us, size: next(
        (p["shift"]["mean_s"] for p in rep["points"]
         if p["gap_work_us"] == gap_us and p["payload_bytes"] == size
         and not p.get("overlapped", False)), None)
    reports = [load(p) for p in sorted(glob.glob(os.path.join(folder, "*.json")))]
    reports = [r for r in reports if r.get("ranks") == 2]
    late = [v for v in (point(r, 10000, 16384) for r in reports) if v]
    if len(late) < 2:
        return ""
    near = [v for v in (point(r, 0, 64) for r in reports) if v]
    span = lambda v, k=1e6: f"{k * min(v):.2f}-{k * max(v):.2f} us (median {k * statistics.median(v):.2f})"
    text = (f"Exchange drift: the {len(reports)} 2-rank exchange benchmarks run through the validation "
            f"put a 16 KB shift after 10 ms of compute at {span(late)}")
    if near:
        text += f", a back-to-back 64 B shift at {span(near)}"
    return text + "; a profile measured once stands for one of them."


def sharing_in_use(d):
    """The time-sharing form the predictions of folder d used (predict --time-sharing-overhead)."""
    for path in sorted(glob.glob(os.path.join(d, "prediction_*.json"))):
        return load(path).get("request", {}).get("time_sharing_overhead", "per-step")
    return "per-step"


def config_label(r):
    return (f"{r['setup']} {r['grid']}{' balanced' if r.get('decomposition') == 'balanced' else ''}"
            f"{' overlap' if r.get('overlap') else ''} s{r['scale']:g} {r['ranks']} x {r['threads']}")


def kept_jobs_lines(validation, d):
    """The targets against the expected error over the main jobs kept in DIR/jobs
    (scripts/keep-job.py, session 78), when DIR/bias.json holds this job; else nothing."""
    path = os.path.join(d, "bias.json")
    if not os.path.exists(path):
        return []
    bias = load(path)
    this = (validation.get("git_commit"), validation.get("timestamp"))
    if this not in {(i.get("git_commit"), i.get("timestamp")) for i in bias.get("inputs", [])}:
        return []  # written before this job: not its history
    t = bias.get("targets_on_expected_error")
    if not t:
        return [f"Over the {len(bias['inputs'])} main jobs kept in `jobs/` (bias.md): too few "
                f"jobs per configuration to set the targets against their mean errors (3 needed)."]
    pct = lambda v: f"{100 * v:.1f} %"
    mark = lambda ok: "met" if ok else "**missed**"
    text = (f"Over the {len(bias['inputs'])} main jobs kept in `jobs/` (bias.md; delete those of "
            f"other code), each configuration's mean error, what the model gets wrong every time: "
            f"median {pct(t['median_abs_mean_error'])} ({mark(t['median_met'])}), max "
            f"{pct(t['max_abs_mean_error'])} ({t['max_configuration']}; "
            f"{mark(t['max_met'])})")
    own_path = os.path.join(d, "bias_own_speed.json")
    own = load(own_path).get("targets_on_expected_error") if os.path.exists(own_path) else None
    if own:
        text += (f"; at each run's own speed {pct(own['median_abs_mean_error'])} / "
                 f"{pct(own['max_abs_mean_error'])}")
    sj = t["single_jobs"]
    return [text + f"; the jobs one by one met both targets in {sj['both_met']} of {sj['jobs']}."]


def summary_lines(validation, args):
    """The headline first: each target against its figure, then what bounds them on this host."""
    s = validation["summary"]
    wall, comm = s.get("wall_abs_error"), s.get("inline_comm_abs_error_per_interval")
    if not wall:
        return []
    pct = lambda v: f"{100 * v:.1f} %"
    mark = lambda v, target: "met" if v <= target else "**missed**"
    rows = [("Total wall time, median \\|error\\| over the validation set", pct(wall["median"]), "5 %",
             mark(wall["median"], 0.05)),
            ("Total wall time, max \\|error\\|", pct(wall["max"]), "10 %", mark(wall["max"], 0.10))]
    if comm:
        rows.append(("Communication (inline prediction), median \\|error\\| per interval",
                     pct(comm["median"]), "20 %", mark(comm["median"], 0.20)))
    lines = ["## Summary", ""]
    if args.quick:
        lines += ["A `--quick` job: smoke sizes that check every stage runs. Its figures mean "
                  "nothing about the model; run the job without `--quick` for them.", ""]
    lines += ["| figure | measured | target | |", "|---|---|---|---|"]
    lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    lines.append("")
    worst = sorted(validation["configurations"], key=lambda r: -abs(r["wall_error"]))[:3]

    def at_own_speed(r):
        # A miss the host's speed explains says so: the run's gauge against the calibration's.
        sg = r.get("speed_gauge") or {}
        if not sg.get("gauge_factor") or sg.get("wall_error") is None:
            return ""
        return (f" (the host {1 / sg['gauge_factor']:.2f} times as fast as for the calibration, "
                f"by the run's speed gauge; {100 * sg['wall_error']:+.1f} % at that speed)")

    lines.append("Largest wall-time errors (prediction against the run as measured): " +
                 ", ".join(f"{config_label(r)} {100 * r['wall_error']:+.1f} %{at_own_speed(r)}"
                           for r in worst) + ".")
    context = []
    own = s.get("wall_abs_error_speed_corrected")
    if own:
        context.append(f"at each run's own host speed (the speed gauge's factor, a diagnostic) median "
                       f"{pct(own['median'])}, max {pct(own['max'])}")
    floor = s.get("wall_noise_floor")
    if floor:
        context.append(f"a model exact in expectation, on single runs as noisy as the calibration "
                       f"runs, would show median {pct(floor['median_abs_error']['median'])}, max "
                       f"{pct(floor['max_abs_error']['median'])} (the noise floor)")
    band = s.get("wall_band")
    if band:
        context.append(f"{band['within']} of {band['count']} configurations measured within their "
                       f"band of +-{band['sds']:g} sd")
    if context:
        lines.append("For scale: " + "; ".join(context) + ".")
    if not args.quick:
        lines += kept_jobs_lines(validation, args.dir)
    if args.calibration_s and args.validation_s:
        lines.append(f"Calibration cost {100 * args.calibration_s / args.validation_s:.0f} % of the "
                     f"wall time of the validation runs it predicts ({args.calibration_s:.0f} s "
                     f"against {args.validation_s:.0f} s).")
    lines += ["", "Everything below is the detail: how the model was built from this host's runs, "
              "each configuration's errors by phase, and every rule chosen after seeing validation "
              "data (marked **tuned**) with the untuned result beside it.", "", "## Detail", ""]
    return lines


def in_sample_lines(d):
    """validation.md's paragraph on the model predicting its own calibration runs
    (scripts/model-set.sh, in_sample; session 77), or nothing without DIR/in-sample."""
    path = os.path.join(d, "in-sample", "validation.json")
    if not os.path.exists(path):
        return []
    v = load(path)
    s = v.get("summary") or {}
    wall, own = s.get("wall_abs_error"), s.get("wall_abs_error_speed_corrected")
    if not wall:
        return []
    text = ("In sample (the model predicting its own calibration runs, each configuration at the "
            "model's reference speed, in-sample/validation.json): what the fit cannot reproduce even "
            "where it was fitted is its form, not its extrapolation. Wall |error| median "
            f"{100 * wall['median']:.1f} %, max {100 * wall['max']:.1f} % over {wall['count']} runs")
    if own:
        text += (f"; at each run's own host speed median {100 * own['median']:.1f} %, max "
                 f"{100 * own['max']:.1f} %")
    by_config = {}  # the repeats of a configuration together: their median error at own speed
    for c in v.get("configurations", []):
        e = (c.get("speed_gauge") or {}).get("wall_error")
        if e is not None:
            shared = " (shared)" if c.get("oversubscribed") else ""
            by_config.setdefault(f"{c['setup']} {c['grid']} s{c['scale']:g} "
                                 f"{c['ranks']} x {c['threads']}{shared}", []).append(e)
    if by_config:
        rows = sorted(((abs(statistics.median(es)), statistics.median(es), name, len(es))
                       for name, es in by_config.items()), reverse=True)
        text += ("; the configurations furthest off at own speed (median of their runs): "
                 + ", ".join(f"{name} {100 * e:+.1f} % ({n} runs)" for _, e, name, n in rows[:3]))
    x = s.get("compute_per_busy_rank_at_own_speed")
    if x:
        text += (f". Each busy rank's compute at its own core's speed within the cores: error median "
                 f"{100 * x['median_error']:+.1f} %, max |error| {100 * x['max_abs_error']:.1f} % over "
                 f"{x['count']} ranks")
    return [text + "."]


def markdown(model, validation, args, out):
    replaying = sharing_in_use(args.dir) == "replay"
    lines = ["# Validation of the SPH runtime model", ""]
    lines.append(f"Host `{validation.get('host')}`, commit `{validation.get('git_commit')}`, "
                 f"{validation.get('timestamp')}.")
    lines.append("")
    lines += summary_lines(validation, args)
    cal = model["calibration_runs"]
    lines.append("Calibration runs (scale, ranks x threads): " +
                 ", ".join(f"{c['setup']} {c['grid']} s{c['scale']:g} {c['ranks']}x{c['threads']} "
                           f"{c['steps']} steps ({c['wall_s']:.1f} s)" for c in cal) + ".")
    for c in model["compute"]:
        lvl = c.get("run_level")
        if not lvl:
            continue
        factors = ", ".join(f"{r['factor']:.2f}" for r in lvl["runs"])
        if lvl.get("rule") == "fastest-repeat":
            takes = ("per setup the fastest run of each repeated configuration, the median over "
                     "configurations (" + ", ".join(
                         f"{k} {v['factor']:.3f} from {v['runs']} runs in {v['configurations']} "
                         f"configuration(s), median run {v['factor_median']:.3f}, mean "
                         f"{v['factor_mean']:.3f}" for k, v in lvl.get("per_setup", {}).items()) + ")")
        else:
            takes = (f"the median run's level ({lvl['factor']:.3f}, mean "
                     f"{lvl.get('factor_mean', float('nan')):.3f}; per setup: " +
                     ", ".join(f"{k} {v['factor']:.3f}" for k, v in lvl.get("per_setup", {}).items()) + ")")
        lines.append(f"Machine drift, {c['grid']} grid at {c['threads']} thread(s): the calibration runs took {factors} times the "
                     f"least-squares fit (spread {lvl['spread_pct']:.0f} %); the model takes {takes}. "
                     f"No prediction here is finer than that spread.")
    for t in model.get("time_sharing", []):
        runs = ", ".join(f"{1e3 * r['overhead_s_per_step']:.3f} ms ({r['overhead']:.2f}x"
                         + (f", at {1e3 * r['shared_compute_s_per_step']:.2f} ms of shared compute"
                            if "shared_compute_s_per_step" in r else "") + ")" for r in t["runs"])
        fit = t.get("overhead_fit")
        uses = (f"the model adds the median, {1e3 * t['overhead_s_per_step']:.3f} ms per step on a "
                f"shared core") if not replaying else (
                f"the per-step form adds the median, {1e3 * t['overhead_s_per_step']:.3f} ms per step "
                f"on a shared core where the model cannot replay the step (ranks of 2 or more threads, "
                f"several nodes; predict --time-sharing-overhead per-step everywhere, the model of "
                f"sessions 34-39)")
        if fit and fit.get("significant"):
            uses += (f" (predict --time-sharing-overhead line would add the line fitted through "
                     f"them, {1e3 * fit['intercept_s_per_step']:.3f} "
                     f"(+-{1e3 * fit['intercept_se_s_per_step']:.3f}) ms + {fit['per_compute']:.3f} "
                     f"(+-{fit['per_compute_se']:.3f}) x the shared core's compute per step, R^2 "
                     f"{fit['r2']:.2f})")
        lines.append(f"Time-sharing overhead at {t['load']:g} processes per core, measured on the app's own "
                     f"calibration runs as time per step beyond the busiest core's summed compute (and as a "
                     f"ratio): {runs}; {uses} (mean {1e3 * t['overhead_s_per_step_mean']:.3f}, spread "
                     f"{1e3 * t['overhead_s_per_step_min']:.3f}-{1e3 * t['overhead_s_per_step_max']:.3f}); "
                     f"until session 34 it multiplied by the median ratio, {t['overhead']:.2f}. Other loads "
                     f"use the exchange benchmark's ratio.")
    b = model.get("time_sharing_bubble")
    if b:
        runs = ", ".join(f"{os.path.basename(r['run'])} phi {r['phi_mean']:.2f}, "
                         f"{100 * r['loss_mean']:+.1f} %" for r in b["runs"])
        lines.append(f"Time-sharing bubble (session 80): each interval of the time-shared calibration "
                     f"runs replayed from its measured CPU per segment, the measured step over the "
                     f"replayed one ({runs}; phi: per core the second busiest rank's CPU over the "
                     f"busiest's, the least over the cores) fits {100 * b['intercept']:+.1f} "
                     f"(+-{100 * b['intercept_se']:.1f}) % + {b['per_phi']:.3f} "
                     f"(+-{b['per_phi_se']:.3f}) x phi over {b['intervals']} intervals; a replayed "
                     f"step where every core time-shares two busy ranks is multiplied by 1 + "
                     f"{b['per_phi']:.3f} phi of its predicted compute (the balanced 4-rank dam "
                     f"break's phi is about 0.65). This k swings between jobs (0.06-0.33 over 51) and "
                     f"does not follow the job's own validation runs (model/NOTES.md, session 80).")
    j = model.get("jitter")
    if j:
        form = j.get("form", "sqrt")
        if form == "proportional":
            k_run, k, k_mean, k_min, k_max, unit, law = ("k_proportional", "k_proportional",
                                                         "k_mean_proportional", "k_min_proportional",
                                                         "k_max_proportional", "k a fraction",
                                                         "k compute")
        else:
            k_run, k, k_mean, k_min, k_max, unit, law = ("k_sqrt_s", "k_sqrt_s", "k_mean_sqrt_s",
                                                         "k_min_sqrt_s", "k_max_sqrt_s", "k in s^0.5",
                                                         "k sqrt(compute)")
        runs = ", ".join(f"{r[k_run]:.4f} ({100 * r['relative_sd_at_run']:.0f} % of "
                         f"{1e3 * r['compute_per_step_s']:.2f} ms)" for r in j["runs"])
        cv = j.get("cv_rms_wait_over_time")
        pct = lambda v: "-" if v is None else f"{100 * v:.2f} %"
        chosen = (f" The form ({form}) was chosen by {j['form_chosen_by']}: square root "
                  f"{pct(cv['sqrt'])}, proportional {pct(cv['proportional'])}.") if cv else ""
        lines.append(f"Step-to-step jitter (standard deviation of a rank's compute per step {law}, "
                     f"from the calibration runs within the cores whose ranks are all busy; {unit}, "
                     f"beside it the relative deviation at the run's own step): {runs}; the model takes "
                     f"the median, k = {j[k]:.4f} (mean {j[k_mean]:.4f}, spread "
                     f"{j[k_min]:.4f}-{j[k_max]:.4f}). Within the cores a step lasts the "
                     f"expected maximum of the ranks' compute + communication.{chosen}")
    lines.append("")
    lines.append("| setup | grid | scale | ranks x threads | steps | measured s | predicted s | wall error | "
                 "band z | compute | comm | wait | idle | pairs | pairs (regression) | exports (edge) | "
                 "exports (regression) | peak RSS (MB, error) |")
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    def band_z(r):
        b = r.get("wall_band")
        if not b:
            return "-"
        return f"{b['z']:+.1f}" + ("" if b["within"] else " (outside)")

    def rss(r):
        m = r.get("peak_rss_bytes")
        return f"{m['measured_max_rank'] / 1e6:.1f}, {100 * m['error']:+.1f} %" if m else "-"

    for r in validation["configurations"]:
        ph = r["phases"]
        pct = lambda v: f"{100 * v:+.1f} %"
        lines.append(
            f"| {r['setup']} | {r['grid']}{' balanced' if r.get('decomposition') == 'balanced' else ''}"
            f"{' overlap' if r.get('overlap') else ''} | "
            f"{r['scale']:g} | {r['ranks']} x {r['threads']}"
            f"{' (shared)' if r['oversubscribed'] else ''} | {r['steps']} | {r['measured_wall_s']:.2f} | "
            f"{r['predicted_wall_s']:.2f} | **{pct(r['wall_error'])}** | {band_z(r)} | "
            f"{pct(ph['compute']['error'])} | "
            f"{pct(ph['comm']['error'])} | {pct(ph['wait']['error'])} | "
            f"{pct(ph['idle']['error']) if ph['idle']['measured_s'] > 0 or ph['idle']['predicted_s'] > 0 else '-'} | "
            f"{pct(r['pairs_per_step']['error'])} | {pct(r['pairs_per_step']['error_regression'])} | "
            f"{pct(r['exported_per_step']['error_edge_columns'])} | "
            f"{pct(r['exported_per_step']['error_regression'])} | {rss(r)} |")
    s = validation["summary"]
    lines.append("")
    if s["wall_abs_error"]:
        lines.append(f"Total wall time |error|: median {100 * s['wall_abs_error']['median']:.1f} %, "
                     f"max {100 * s['wall_abs_error']['max']:.1f} % (targets 5 % and 10 %).")
        gauge = model.get("speed_gauge") or {}
        corrected = s.get("wall_abs_error_speed_corrected")
        if gauge.get("applied"):
            factors = [r["factor"] for r in gauge["runs"]]
            per_interval = gauge.get("mode") in ("interval", "interval-mean")
            line = (f"Speed gauge (sph --speed-gauge-every: a fixed piece of the density pass's "
                    f"arithmetic timed on every thread every few steps, model/NOTES.md sessions 50-51): the "
                    f"calibration runs ran at {min(factors):.2f}-{max(factors):.2f} times the median run's "
                    f"gauge time (sd of ln {100 * gauge['log_sd']:.1f} %), and every time they measured is "
                    + ("divided by the factor of the gauge around it (each interval's, pooled over +-1 "
                       "interval as the compute-weighted "
                       + ("median: calibrate --speed-gauge interval)" if gauge.get("mode") == "interval"
                          else "mean: calibrate --speed-gauge interval-mean)") if per_interval else
                       "divided by their run's factor (calibrate --speed-gauge run)")
                    + ", so the model is at one host speed.")
            mean_factor = (gauge.get("mean_factor") or {}).get("value")
            if mean_factor:
                line += (f" Over the calibration's compute the host ran on average at "
                         f"{mean_factor:.3f} times the median run's time (mean_factor; below 1 its "
                         f"fast spells); the model is at the median run's speed, and predict "
                         f"--host-speed mean puts a prediction at the mean over the calibration "
                         f"runs of its own grid, thread count and setup")
                per_setup = (gauge.get("mean_factor") or {}).get("per_setup") or []
                if per_setup:
                    line += " (" + ", ".join(
                        f"{r['grid']} at {r['threads']} thread(s) on {r['setup']} {r['value']:.3f}"
                        for r in per_setup) + ")"
                line += (": the long single runs here, see below (model/NOTES.md, sessions "
                         "74-76).")
            elasticity = gauge.get("elasticity")
            beta = elasticity.get("used", 1.0) if elasticity else 1.0
            between = (elasticity or {}).get("between_repeats")
            if between:
                line += (f" Between the repeats of one configuration the runs' compute follows "
                         f"the gauge with an elasticity of {between['value']:.2f} (standard error "
                         f"{between['se']:.2f}, {between['runs']} runs of "
                         f"{between['configurations']} configurations: ln compute per interaction "
                         f"on ln of the run's whole gauge, a level per configuration)")
                if "value" in elasticity:
                    line += (f"; within runs it reads {elasticity['value']:.2f} (standard error "
                             f"{elasticity['se']:.2f}, each interval on the gauge around it), "
                             f"flattened by the noise of a 30 us gauge sample (model/NOTES.md, "
                             f"session 74)")
                line += ", "
            elif elasticity and "value" in elasticity:
                line += (f" The runs' compute follows the gauge with an elasticity of "
                         f"{elasticity['value']:.2f} (standard error {elasticity['se']:.2f}, "
                         f"{elasticity['points']} busy rank-intervals: ln compute per interaction on "
                         f"ln gauge, each run and rank's own level and trend through the run apart), ")
            if between or (elasticity and "value" in elasticity):
                line += (f"so each factor is applied raised to {beta:.2f} (calibrate "
                         f"--speed-gauge-elasticity fitted)." if beta != 1 else
                         f"and the factor is applied whole ({elasticity.get('reason', '')}; "
                         f"raised to the elasticity in gauge-elasticity-fitted/).")
            if corrected:
                f = s["speed_factor"]
                line += (f" The validation runs ran at {f['min']:.2f}-{f['max']:.2f} times it; at each "
                         f"run's own host speed (the prediction times its factor"
                         + (f" raised to {beta:.2f}" if beta != 1 else "")
                         + f") the wall |error| is "
                         f"median {100 * corrected['median']:.1f} %, max {100 * corrected['max']:.1f} % over "
                         f"{corrected['count']} configurations. That corrects for the host, not the model, and "
                         f"uses what the run measured: the figures above are the prediction's.")
            one = model.get("level_scatter_at_one_speed", {}).get("per_threads", [])
            if one:
                line += (" At one speed the calibration runs scatter about their setup's level by " +
                         ", ".join(f"{100 * e['log_sd']:.1f} % at {e['threads']} thread(s)" for e in one) +
                         " (the band below is of the runs as measured).")
            lines.append(line)
        elif gauge:
            lines.append(f"Speed gauge not applied: {gauge.get('reason', '')}.")
        # The vCPUs' latency mode of the runs of two threads (sph's core latency gauge).
        cal_lat = model.get("core_latency") or []
        val_lat = [r for r in validation["configurations"] if r.get("core_latency")]
        if cal_lat or val_lat:
            far_s = (cal_lat or [r["core_latency"] for r in val_lat])[0]["far_above_s"]
            far_runs = sum(c["far_fraction"] > 0.5 for c in cal_lat)
            line = (f"Core latency (sph's gauge: a cache line passed between threads 0 and 1, far "
                    f"above {far_s * 1e9:.0f} ns; this VM's vCPUs switch between about 60 and "
                    f"350 ns in spells, sph/NOTES.md session 70): ")
            if cal_lat:
                line += (f"the calibration runs of 2 threads read {min(c['round_trip_s'] for c in cal_lat) * 1e9:.0f}-"
                         f"{max(c['round_trip_s'] for c in cal_lat) * 1e9:.0f} ns, {far_runs} of "
                         f"{len(cal_lat)} mostly far")
            if val_lat:
                line += ("; " if cal_lat else "") + "the validation runs " + ", ".join(
                    f"{r['setup']} {'+'.join(r['grid']) if isinstance(r['grid'], list) else r['grid']} "
                    f"s{r['scale']:g} {r['ranks']} x {r['threads']}: "
                    f"{r['core_latency']['round_trip_s'] * 1e9:.0f} ns "
                    f"({100 * r['core_latency']['far_fraction']:.0f} % far), wall error "
                    f"{100 * r['wall_error']:+.1f} %" for r in val_lat)
            # The compute term that costs it (calibrate offers it where every point measured it).
            for c in model.get("compute", []):
                rt = c.get("core_round_trip_s")
                if not rt:
                    continue
                what = f"{c['grid']} at {c['threads']} threads"
                if "core_round_trips" in c.get("coefficients", {}):
                    k = c["coefficients"]["core_round_trips"]
                    line += (f"; the compute fit of {what} costs {k['value']:.0f} round trips a step "
                             f"(standard error {k['se']:.0f}) and every prediction puts in the calibration "
                             f"rank-intervals' mean round trip, {rt['mean'] * 1e9:.0f} ns (what a sum of steps "
                             f"pays over both modes), where their median is {rt['median'] * 1e9:.0f} ns "
                             f"({rt['min'] * 1e9:.0f}-{rt['max'] * 1e9:.0f}, {100 * rt['far_fraction']:.0f} % "
                             f"far): a step at the median costs {k['value'] * (rt['mean'] - rt['median']) * 1e6:.1f} us "
                             f"less")
                else:
                    line += (f"; the compute fit of {what} was offered the round trip as a cost term "
                             f"and its cross-validation left it out")
            lines.append(line + ".")
        band = s.get("wall_band")
        scatter = model.get("level_scatter", {}).get("per_threads", [])
        if band and scatter:
            per = ", ".join(f"{100 * e['log_sd']:.1f} % at {e['threads']} thread(s) ({e['runs']} runs, "
                            f"{e['dof']} degrees of freedom)" for e in scatter)
            lines.append(f"The calibration runs scatter about their setup's level by {per} (standard "
                         f"deviation of ln(time), pooled over the grids); each prediction carries a band of "
                         f"+-{band['sds']:g} of it (`wall_band`; column \"band z\": ln(measured / predicted) in "
                         f"those deviations). Measured within the band: {band['within']} of {band['count']} "
                         f"configurations, median |z| {band['median_abs_z']:.2f}. The band is how far one run "
                         f"on this host may land from a right prediction, not a target: where it is wider than "
                         f"the 10 % target, a miss inside it is within this host's own run-to-run noise.")
        floor = s.get("wall_noise_floor")
        if floor:
            q = lambda k: (f"{100 * floor[k]['median']:.1f} % (90 % of draws "
                           f"{100 * floor[k]['p05']:.1f}-{100 * floor[k]['p95']:.1f})")
            lines.append(f"Noise floor: a model exact in expectation, on runs as noisy as the calibration "
                         f"runs (each configuration's measured time drawn {floor['draws']} times as the "
                         f"prediction x exp(sd z) with its band's sd, `wall_noise_floor`), would show a "
                         f"median |error| of {q('median_abs_error')} and a max of {q('max_abs_error')}. "
                         f"Where these are above the targets (5 and 10 %), no model could meet them on this "
                         f"host's single runs; the gap between these and the figures above is what the "
                         f"model adds (model/NOTES.md, session 46, measures the scatter apart, by run "
                         f"length).")
        def untuned(subdir):
            """The same runs through an earlier model beside the results: its wall |error| line."""
            other = os.path.join(args.dir, subdir, "validation.json")
            if not os.path.exists(other):
                return None
            o = load(other)["summary"]["wall_abs_error"]
            return (f"median {100 * o['median']:.1f} %, max {100 * o['max']:.1f} % over {o['count']} "
                    f"configurations")

        def order_time():
            """The memory-order time rule the scale-1 table prediction used."""
            path = os.path.join(args.dir, "prediction_dambreak_s1_table.json")
            if not os.path.exists(path):
                return None
            return (load(path).get("model_source") or {}).get("memory_order_time")

        def carry_share():
            """The cost's share of the memory order's carry the scale-1 table prediction used."""
            path = os.path.join(args.dir, "prediction_dambreak_s1_table.json")
            if not os.path.exists(path):
                return None
            return (load(path).get("model_source") or {}).get("memory_order_carry")

        def host_speeds():
            """Each prediction's predict --host-speed rule and factor, by prediction file."""
            out = {}
            for path in sorted(glob.glob(os.path.join(args.dir, "prediction_*.json"))):
                hs = load(path).get("host_speed")
                if hs:
                    out[os.path.basename(path)[len("prediction_"):-len(".json")]] = hs
            return out

        speeds = host_speeds()
        at_mean = sorted(k for k, v in speeds.items() if v.get("rule") == "mean")
        mean_factors_used = ", ".join(f"{k} {v['factor']:.3f}" for k, v in sorted(speeds.items())
                                      if v.get("rule") == "mean")
        per_setup_used = any("per_setup" in (v.get("source") or "") for v in speeds.values())
        # Each tuned choice beside the model before it, on the same runs: (in use, folder, line).
        choices = [
            (bool(at_mean) and per_setup_used,
             "pooled-mean-host-speed",
             "The long single validation runs at the host's mean speed over the calibration runs "
             "of their own grid, thread count and setup (predict --host-speed mean, "
             "speed_gauge.mean_factor.per_setup: " + mean_factors_used + "), since session 76: "
             "the model at that speed predicts its own calibration runs as measured, where the "
             "mean over every run (session 75) left the list and table dam breaks' busy ranks "
             "+2 to +4 % high, as their runs ran in faster spells than the still tanks' (over 23 "
             "Zen 4 jobs a factor of 0.95-0.96 against 1.00). Decided after replaying those jobs "
             "and seven earlier-host ones (Zen 4: mean of the jobs' wall medians 6.21 -> 5.65 %, "
             "maxes 21.1 -> 20.2 %, all their configurations within 10 % 73 -> 77 %; earlier hosts "
             "4.30 -> 4.60 and 12.4 -> 11.9 %): **tuned**. At the mean over every calibration run "
             "(session 75's rule) on the same runs: {o} (pooled-mean-host-speed/validation.json)."),
            (bool(at_mean) and len(at_mean) < len(speeds),
             "median-host-speed",
             "The long single validation runs (" + ", ".join(at_mean) + ") predicted at the "
             "host's mean speed over the calibration (predict --host-speed mean), the others at "
             "the median calibration run's (--host-speed median), since session 75: a sum of "
             "step times pays the host's fast spells in their share, and runs of 8-30 s span "
             "them (5-60 s here) where the median of three short runs lands on the median; over "
             "nineteen Zen 4 main jobs the list and table dam breaks had come out +8 to +13 % as "
             "measured (scripts/model-bias.py), +5 to +10 % with it. Decided after replaying "
             "those jobs and seven earlier-host ones (Zen 4: mean of the jobs' wall medians 6.94 "
             "-> 6.31 %, maxes 22.5 -> 20.7 %; earlier hosts 4.23 -> 4.30 and 12.7 -> 12.4 %; "
             "every prediction at the mean: 6.45 and 20.6, 4.54 and 12.6 %): **tuned**. Every "
             "prediction at the median run's speed (sessions 50-74) on the same runs: {o} "
             "(median-host-speed/validation.json)."),
            ({c.get("term_selection", "pooled-one-percent") for c in model["compute"]} == {"levelled-best"},
             "levelled-one-se",
             "Compute-cost terms chosen by levelled-best (a cost level per setup, the set with the best "
             "cross-validation score), a rule picked in session 64 after replaying eight main jobs' runs "
             "(sessions 61-63) under it and under the rule before: **tuned** against validation data. "
             "Untuned, the rule before (levelled-one-se, sessions 13-63: the smallest set within one "
             "standard error of the best score) on the same runs: {o} (levelled-one-se/validation.json)."),
            ({c.get("term_selection", "pooled-one-percent") for c in model["compute"]} != {"pooled-one-percent"},
             "pooled-one-percent",
             "A cost level per setup in the fit and its cross-validation (session 13, after comparing six "
             "rules on three main jobs' runs: **tuned**). The rule before it (pooled-one-percent: one "
             "pooled fit, a term kept for a 1 % better score) on the same runs: {o} "
             "(pooled-one-percent/validation.json)."),
            ({c.get("fit_weights", "absolute") for c in model["compute"]} == {"relative"},
             "absolute-weights",
             "Cost fit weighted per unit of each calibration run's step (calibrate --fit-weights relative, "
             "so a small-scale run's per-step cost counts as much as a large run's), chosen in session 31 "
             "after seeing the 2-thread dam break's errors: **tuned**. With absolute weights (seconds per "
             "step, session 30's model) on the same runs: {o} (absolute-weights/validation.json)."),
            (any(c.get("time_profile") for c in model["compute"]),
             "no-profile",
             "Cost over Froude time (calibrate --time-profile froude: the fit times the calibration runs' "
             "measured / fitted compute at the target's Froude time, no descents term), chosen in session 16 "
             "after seeing the scale-1 dam-break errors: **tuned**. Without it (the fit alone, descents read "
             "at simulated time, session 15's model) on the same runs: {o}, those it can predict from these "
             "calibration runs (no-profile/validation.json; refusals, if any, in no-profile/refused.txt)."),
            (any(p.get("smoothing") == "robust quadratic" for c in model["compute"]
                 for p in (c.get("time_profile") or {}).values() if isinstance(p, dict)),
             "windowed-profile",
             "The Froude-time profile a quadratic fitted by robust least squares (bisquare) to the "
             "calibration intervals' measured / fitted compute, chosen in session 42 after replaying "
             "20 stored main jobs (the scale-2 dam breaks read their whole run off the profile's first "
             "0.035 s of Froude time, where one slow spell in one calibration run bent the moving "
             "ratio by 10-20 %: on 4 ranks 3 of 20 beyond 10 % with it, none with the quadratic): "
             "**tuned**. With the moving ratio over +-2 intervals (sessions 16-41) on the same runs: "
             "{o} (windowed-profile/validation.json)."),
            (any("overhead_s_per_step" in t for t in model.get("time_sharing", [])),
             "ratio-overhead",
             "Time-sharing overhead added in seconds per step on a shared core (predict "
             "--time-sharing-overhead per-step; since session 40 only where the step is not replayed), "
             "chosen in session 34 after the table still tank on 3 ranks came out 2-16 % high in 13 of "
             "14 main jobs: **tuned**. As a ratio on the shared core's compute (the model before it, "
             "everywhere above the cores) on the same runs: {o} (ratio-overhead/validation.json)."),
            (any(c.get("run_level", {}).get("rule") == "pooled" for c in model["compute"]),
             "fastest-repeat",
             "Per setup, the cost level of all its calibration runs pooled through the Froude-time "
             "profile (calibrate --run-level pooled: a mean, which is what a sum of step times "
             "pays), back in session 45 after seven main jobs on the VM's Intel host (session "
             "44's last, session 45's six), where the fastest run of each repeated configuration "
             "(sessions 43-44) sat below the long runs: mean signed error +0.6 % pooled against "
             "-6.9 % (per job +1.6, -3.7, -0.6, +10.3, +0.7, -0.3, -4.0 against -3.9, -9.0, "
             "-12.8, +0.1, -5.2, -10.0, -7.7 %), mean per-job median 8.1 against 9.2 %, mean max "
             "25.0 against 28.0 %; on the AMD host's "
             "23 stored jobs the fastest repeat had been a little better (mean per-job median "
             "3.27 against 3.47 %): **tuned**. With session 46's five jobs (in three of them the "
             "calibration ran slower than the validation) the twelve Intel jobs' means are 10.8 "
             "against 9.6 % (median), 28.4 against 27.2 % (max), +4.9 against -4.1 % (signed), "
             "pooled lower in 7 of 12 on both the median and the max: within the jobs' noise "
             "either way, so the rule stays (model/NOTES.md, session 46). With each "
             "repeated configuration's fastest run on "
             "the same runs: {o} (fastest-repeat/validation.json)."),
            ((model.get("speed_gauge") or {}).get("applied", False),
             "no-speed-gauge",
             "Calibration runs put at one host speed by the speed gauge, chosen in session 50 from "
             "the gauge's agreement with repeated runs (model/NOTES.md), before any validation ran "
             "with it: not tuned. Without it (the runs as measured, sessions 1-49's model) on the "
             "same runs: {o} (no-speed-gauge/validation.json)."),
            ((model.get("speed_gauge") or {}).get("applied", False)
             and ((model.get("speed_gauge") or {}).get("elasticity") or {}).get("used", 1.0) == 1.0,
             "gauge-elasticity-fitted",
             "The gauge's factor applied whole (calibrate --speed-gauge-elasticity one, sessions "
             "50-74): kept in session 70 after the elasticity within runs (each interval's "
             "compute per interaction on its gauge, 0.38-0.88) made the wall median worse in six "
             "of ten replayed jobs; in session 74 that estimate proved flattened by the gauge "
             "sample's noise: between repeats of one configuration, pooled over sixteen jobs on "
             "this VM's Zen 4 host, it reads 0.92 for Cell+List and Cell+Table and 1.01 for "
             "Cell+Sorted (standard errors 0.03), and each job's estimate between repeats is "
             "above its estimate within runs in 23 of 23 jobs: not tuned. With each factor "
             "raised to this job's elasticity between repeats (1 where its standard error is "
             "above 0.1) on the same runs: {o} "
             "(gauge-elasticity-fitted/validation.json)."),
            ("form_chosen_by" in (model.get("jitter") or {}),
             "sqrt-jitter",
             "The jitter's form chosen by the calibration runs' own waits (calibrate --jitter-form "
             "auto, since session 61: the square root or proportional, whichever predicts each "
             "all-busy run's wait from the others' better; a Cell+Table still tank at 0.7 in "
             "rounds a and b gives the runs a range of steps), built after session 60's still tanks "
             "on 2 ranks waited twice what the square root predicted (8 % of their compute at "
             "1.8-25 ms steps alike) and eight stored jobs were replayed: **tuned**. With the "
             "square root always (sessions 15-60, itself chosen in session 15 after seeing "
             "validation waits) on the same runs: {o} (sqrt-jitter/validation.json)."),
            (True,
             "walls-term",
             "The compute-cost term walls (every wall particle of a rank) no longer offered to "
             "the term selection, since session 51: a rank's dry walls measured to cost nothing "
             "(under 0.2 us each, where the fit had put 2.7 us), but the change was decided "
             "after seeing session 50's stored job's misses and replaying five jobs (only one of "
             "them chose walls: 8.6 / 21.2 % with it, 8.0 / 17.5 % without): **tuned**. With walls "
             "offered (calibrate --walls-term, sessions 1-50's candidates) on the same runs: {o} "
             "(walls-term/validation.json)."),
            ((model.get("speed_gauge") or {}).get("mode") == "run",
             "interval-speed-gauge",
             "The gauge applied as one factor per calibration run (calibrate --speed-gauge run), "
             "since session 85 (and session 50): the reference speed is the median of the runs' "
             "whole gauges (a mean over each run's samples), while an interval's factor is a "
             "compute-weighted median over +-1 interval of few, right-skewed samples (a host "
             "interrupt inflates one), so it sits below its run's and the calibration runs came "
             "out 1.2-2.1 % dearer per interval than per run (35 main jobs' runs, every "
             "calibration configuration; 0.3-0.9 % in the validation runs' longer intervals). "
             "Decided after seeing validation: 24 stored main jobs replayed and the 11 others' "
             "run-speed-gauge/ beside (configurations with a systematic error 10 -> 5 and 10 -> 8 "
             "of 19, the sorted 2-rank dam break +4.1 -> +1.4 % and +4.0 -> +1.6 %, single jobs "
             "within both targets 15 -> 17 of 35); on the 29 stored jobs of sessions 51-84 "
             "(older models, two hosts) per interval had been a little better (mean median / max "
             "4.22 / 14.10 against 4.43 / 14.86 %): **tuned**. With the gauge per interval "
             "(sessions 51-84) on the same runs: {o} (interval-speed-gauge/validation.json)."),
            ((model.get("speed_gauge") or {}).get("mode") == "interval",
             "run-speed-gauge",
             "The gauge applied per interval (calibrate --speed-gauge interval: each interval's "
             "gauge pooled over +-1 interval), chosen in session 51 from the calibration runs "
             "alone (between repeated rounds of a configuration the cost's shape over the run "
             "differed by 11.1 % with one factor per run, 7.8 % per interval; model/NOTES.md) and "
             "then replayed on two main jobs' runs (median / max 6.9 / 26.9 and 13.7 / 32.7 % per "
             "run, 8.6 / 21.2 and 11.8 / 31.9 % per interval), before the default changed: "
             "**tuned** (the replay was seen). With one factor per run (session 50's model) on "
             "the same runs: {o} (run-speed-gauge/validation.json)."),
            (any(r["path"].endswith("_c.json") for r in model["calibration_runs"]),
             "two-rounds",
             "Cell+Sorted calibrated on rounds a, b and c (a median run's level per setup then), "
             "chosen in session 42 after replaying the 21 stored main jobs of "
             "sessions 37-42 (max within 10 % in 12 jobs against 10, mean max 11.6 % against 12.6 %, "
             "configurations beyond 10 %: 22 against 29): **tuned**. With rounds a and b only "
             "(sessions 38-41's calibration, Cell+List and Cell+Table on round a) on the same "
             "validation runs: {o} (two-rounds/validation.json)."),
            (any("_list_b" in r["path"] or "_table_b" in r["path"]
                 for r in model["calibration_runs"]),
             "round-a-list-table",
             "Cell+List and Cell+Table calibrated on rounds a and b, chosen in session 44 after "
             "its three main jobs on the VM's noisier Intel host (median / max 10.7 / 23.8, 7.9 / "
             "22.1, 6.5 / 19.5 % against 13.7 / 29.4, 9.3 / 42.4, 8.3 / 23.7 % with round a only; "
             "on the AMD host's 23 stored jobs 3.30 / 11.3 against 3.47 / 11.7 %): **tuned**. With "
             "round a only (sessions 38-43's calibration) on the same validation runs: {o} "
             "(round-a-list-table/validation.json)."),
            (any("dambreak_s0.5_list_b" in r["path"] or "dambreak_s0.5_table_b" in r["path"]
                 for r in model["calibration_runs"]),
             "long-dambreak-round-a",
             "Cell+List's and Cell+Table's long dam breaks (at scale 0.35 in sessions 46-54, 0.5 "
             "since) in round b as well, added in session 46 after its first main job, where they "
             "ran in round a only (sessions 44-45) and a slow spell on round a (1.38 times the fit, "
             "round b 0.80-0.86) put every list and table dam break 33-51 % high: past 0.036 s of "
             "Froude time they are the only list or table runs: **tuned**. With round a's alone "
             "on the same validation runs: {o} (long-dambreak-round-a/validation.json)."),
            ("by_column" in (model.get("disorder") or {}).get("dambreak", {}).get("table", {})
             and order_time() == "froude",
             "simulated-order",
             "Each equal slab's Cell+Table memory order read with its columns at the target's "
             "Froude time (predict --memory-order-time froude), since session 90 (and in sessions "
             "56-58): over 90 main jobs of sessions 82-90, each with the other rule beside on the "
             "same runs, the list and table dam breaks' mean errors were +0.9 to +7.1 % with the "
             "order carried to simulated time (the 4-rank scale-2 table dam break +7.1 % at 1000 "
             "steps, the 1-4 rank scale-1 ones +1.2 / +0.9 / +2.7 / +3.1 %) and -1.6 to +3.9 % at "
             "Froude time (+3.8 %; -1.2 / -1.6 / +0.6 / +1.5 %), the jobs' max 0.22 points lower "
             "(standard error 0.09), both targets met in 50 jobs against 49: **tuned**. It is a "
             "compensation, not a better order: read at Froude time the descents per interaction "
             "come out about 30 % under the runs' (validate's memory-order term; -3 % carried to "
             "simulated time), and that offsets the whole water's Froude-time cost profile, "
             "which a quiet back rank does not follow (model/NOTES.md, session 90). With the "
             "order carried to the whole "
             "water's at simulated time and half of the cost's carry (sessions 73-89) on the same "
             "runs: {o} (simulated-order/validation.json)" + (
                 f"; with all of the carry (sessions 59-72): {untuned('full-carry')} "
                 "(full-carry/validation.json)." if untuned("full-carry") else ".")),
            ("by_column" in (model.get("disorder") or {}).get("dambreak", {}).get("table", {})
             and order_time() == "columns",
             "froude-order",
             "Each equal slab's Cell+Table memory order read from its own columns at the "
             "target's simulated time (predict --memory-order-time columns), since session 91: "
             "the calibration record's per-column descents per interaction at the same simulated "
             "time, columns at their relative place, came within 0-8 % of the back and front "
             "ranks' own counts in the 4-rank dam breaks at scales 1 and 2, where read at Froude "
             "time (session 90) the back rank's were 41 % low at scale 2; the whole water's cost "
             "still follows the Froude-time profile. Replayed on 92 stored main jobs of sessions "
             "82-90 against Froude time: the 4-rank scale-2 table dam break's mean error +3.9 -> "
             "+2.2 %, the 3- and 4-rank scale-1 ones +0.4 / +1.3 -> -0.5 / -0.9 %, the jobs' max "
             "0.13 points lower (standard error 0.06), both targets met in 55 jobs either way: "
             "**tuned** (model/NOTES.md, session 91). With the order at Froude time (session 90) "
             "on the same runs: {o} (froude-order/validation.json)" + (
                 f"; carried to the whole water's at simulated time (sessions 73-89): "
                 f"{untuned('simulated-order')} (simulated-order/validation.json)."
                 if untuned("simulated-order") else ".")),
            ("by_column" in (model.get("disorder") or {}).get("dambreak", {}).get("table", {})
             and order_time() == "simulated",
             "froude-order",
             "Each equal slab's Cell+Table memory order carried to the whole water's at the "
             "target's simulated time (predict --memory-order-time simulated), since session 59: "
             "the columns follow the flow (Froude time), but the descents per interaction follow "
             "simulated time (the particles' jitter), and a scale-1 dam break, which at equal "
             "Froude time has run 1.41 times as long as the half-scale record, reads 0.31 descents "
             "per interaction at 0.15 s where the record carried 0.23 (validate's memory-order "
             "term on equal slabs: -26 % median at Froude time). Cell+Table's id sort works by its "
             "descents: over 19 stored jobs its scale-1 cost per interaction over the half-scale "
             "record's at equal Froude time rose from 0.91 to 1.08 through the run, Cell+List's "
             "from 0.92 to 0.95. Not Cell+List (its lists come out reversed whatever the order), "
             "not balanced slabs (their re-cuts refile the particles, which keep their order). The "
             "list and table dam breaks at 0.5 reach the validation's simulated time for it (1000 "
             "steps since session 60, whose scale-1 validation dam breaks run 1000 steps; 1500 "
             "in session 59, 1100 in sessions 55-58). "
             "Decided after replaying 22 stored jobs with their record extended linearly (the "
             "scale-1 table dam breaks on 1-3 ranks -4.5 / -5.9 / -4.0 % on average, +1.6 / +0.1 / "
             "+1.2 % with it; both targets met in 14 of the 22 jobs against 12): **tuned**. With "
             "the order at Froude time (sessions 56-58) on the same runs: {o} "
             "(froude-order/validation.json)."),
            ("gauge" in ((model.get("disorder") or {}).get("dambreak", {}).get("table", {})
                         .get("by_column") or {}),
             "interval-order-line",
             "Cell+Table's memory-order cost line fitted again on each rank-interval's times over "
             "its own kernel's time per interaction (calibrate --order-line-gauge "
             "interval-or-kernel), since session 93, where the line on the interval gauge's "
             "times is unusable (its slope within two standard errors), as in this job: the "
             "kernel runs on the same core over the same particles, so it gauges the host's "
             "speed in every rank-interval, where a noisy spell flattened the one long run's "
             "line in three of session 93's four blind jobs, which then priced every slab at the "
             "whole water's order. It takes out the kernel's own small rise with the order too "
             "(the slope 35 % lower than the interval gauge's on session 91's stored job). "
             "Replayed on those three jobs' runs: the 4-rank scale-2 table dam break at each "
             "run's own speed +6.8 / +6.3 / +15.6 -> +2.2 / +2.2 / +13.3 %, the scale-1 one +0.7 "
             "/ -0.5 / +10.4 -> -3.6 / -4.5 / +8.2 %, the jobs' max as measured 13.2 / 19.7 / "
             "18.8 -> 13.2 / 21.8 / 17.7 %: **tuned** (model/NOTES.md, session 93). With the "
             "line refused (sessions 91-92) on the same runs: {o} "
             "(interval-order-line/validation.json)."),
            (any(c.get("item_cost_bound") == "particle" for c in model["compute"]),
             "unbounded-items",
             "Term sets that price one item (a particle, a ghost, a cell move, a wall) above a fluid "
             "particle's interactions refused (calibrate --item-cost-bound particle), since session "
             "73: a ghost or a cell move is part of a particle's work, and in Cell+List and "
             "Cell+Table runs the cell moves are the ghosts, absent from the 1-rank calibration "
             "runs; the second main job of session 73 priced them at 5.8 us each (its cross-"
             "validation 1.3 % better than interactions alone, the standard error 24 %) and put "
             "the 3-4 rank table dam breaks 29-62 % high, as session 33's 11 us had. Added after "
             "that validation: **tuned** (over 18 replayed jobs it changed two fits, both for the "
             "better). In this calibration it refused "
             + str(sum(bool(cand.get("item_above_a_particle")) for c in model["compute"]
                       for cand in c.get("candidates", [])))
             + " term set(s). Without it (any positive cost, sessions 1-72) on the same runs: {o} "
             "(unbounded-items/validation.json)."),
            (carry_share() not in (None, 1.0),
             "full-carry",
             "The cost of that order following half of its carry from Froude time to simulated "
             "time (predict --memory-order-carry 0.5; the order itself carried whole), since "
             "session 73: validate's cost per interaction over each run's last third against "
             "its first put the cost's rise through the scale-1 table dam breaks 5-6 % above the "
             "runs' with all of it on the Zen 4 host (10 jobs) and -1 to +5 % on the earlier "
             "hosts (7 stored jobs), 0-3 % below and 0-7 % below at Froude time: the share that "
             "zeroes it is about 0.3 on the one and 0.6-1 on the others, and no calibration run "
             "measures it (model/NOTES.md, session 73). Half is the share least wrong on either; "
             "decided after replaying those 17 jobs (mean of the jobs' wall medians 8.05 -> 7.64 "
             "% and 4.14 -> 4.23 %, at each run's own speed 5.90 -> 5.56 and 4.18 -> 3.56 %): "
             "**tuned**. With all of the carry (sessions 59-72) on the same runs: {o} "
             "(full-carry/validation.json)."),
            (any("_s0.35_sorted_t2_" in r["path"] for r in model["calibration_runs"]),
             "two-thread-one-scale",
             "Cell+Sorted at 2 threads calibrated on its dam break at two scales (0.35 and 0.7) and "
             "its still tank at 0.5, since session 52: a scale sweep (0.35-1.4, 1 x 2, per unit of "
             "the speed gauge) measured about 0.12 ms per 2-thread step whatever its work "
             "(interactions + const within 2 %, interactions alone -16 to +9 %), which one dam-break "
             "scale cannot tell from the cost of an interaction; the 1 x 2 dam break at scale 1 had "
             "come out high in 10 of the 13 stored jobs on this host (mean +12.8 %), and three "
             "stored jobs were replayed before the change: **tuned**. With the dam break at 0.7 "
             "only (sessions 37-51's calibration) on the same runs: {o} "
             "(two-thread-one-scale/validation.json)."),
            (any("_s0.25_sorted_" in r["path"] for r in model["calibration_runs"]),
             "sorted-one-scale",
             "Cell+Sorted's 1-thread runs at a second scale, its dam break at 0.25 on 1 rank "
             "(300 steps, rounds a, b and c), since session 58: with every 1-thread Cell+Sorted "
             "run at 0.5, cross-validation kept interactions alone, and on the 512-bit build "
             "(SPHPERF_VECTOR_WIDTH) a scale-1 dam break on 2 ranks cost 8-9 % less per "
             "interaction than the 0.5 one; the sorted 2-rank runs came out +7 to +13 % in the "
             "session's first three main jobs, and one of them was replayed with such runs made "
             "afterwards before the change: **tuned**. Without them (sessions 37-57's "
             "calibration) on the same runs: {o} (sorted-one-scale/validation.json)."),
            (any(re.search(r"_s0\.7_sorted_[abc]\.json$", r["path"])
                 for r in model["calibration_runs"]),
             "sorted-two-scales",
             "Cell+Sorted's 1-thread dam break at a third scale, 0.7 on 2 ranks (500 steps, "
             "rounds a, b and c), since session 81: with two scales every two-term fit passes "
             "through both, and cross-validation chose interactions + cell moves or + owned "
             "particles in 54 of 62 replayed jobs by under 0.1 % of score, both about 6-8 % high "
             "at scale 1; a scale sweep (0.25-2, 2 ranks) fits interactions + 24 us a step "
             "within 1.4 % at every scale. The sorted 2-rank runs were +6.9 % over 59 jobs; "
             "24 of them were replayed with such runs made afterwards before the change: "
             "**tuned**. Without them (sessions 58-80's calibration) on the same runs: {o} "
             "(sorted-two-scales/validation.json)."),
            ((model.get("speed_gauge") or {}).get("mode") == "interval",
             "mean-gauge-window",
             "An interval's speed gauge as the compute-weighted median over +-1 interval "
             "(calibrate --speed-gauge interval), since session 54: a gauge sample is 30 us of "
             "arithmetic, and 2 % of the calibration runs' rank-intervals read 1.3-4.3 times "
             "their run's median while the interval's compute did not move (a host interrupt "
             "inside the sample); the window's mean took each for a slowdown of three intervals, "
             "which in session 54's second job put one 0.25 run 15 % off its twin and hid a "
             "list step's fixed cost from cross-validation. Decided after seeing two main jobs' "
             "validation: **tuned**. With the window's mean (sessions 51-53) on the same runs: "
             "{o} (mean-gauge-window/validation.json)."),
            (any("_s0.25_list_" in r["path"] or "_s0.25_table_" in r["path"]
                 for r in model["calibration_runs"]),
             "list-table-two-scales",
             "Cell+List's and Cell+Table's dam breaks at a third scale, 0.25, on 1 rank (300 steps, "
             "rounds a and b), since session 54: a scale sweep (0.25-2, 2 ranks, per unit of the "
             "speed gauge) measured about 0.2-0.25 ms per list or table step beyond its "
             "interactions (interactions + const within 3 % at every scale, interactions alone "
             "-13 % at 0.25 to +5 % at 2), which the dam breaks at 0.35 and 0.7 alone could not "
             "tell from run-to-run noise; on 1 rank because on 2 ranks, as every other list or "
             "table run, owned particles and interactions move together and cross-validation "
             "traded one for the other (the 2-rank table dam break predicted 8 % under its 1-rank "
             "twin). Added after the session's main jobs put the scale-2 table dam breaks +11 and "
             "+19 % high and then the 2-rank one -10 to -12 %: **tuned**. Without them (sessions "
             "46-53's calibration) on the same runs: {o} (list-table-two-scales/validation.json)."),
            (any("by_column" in grid for setup in (model.get("disorder") or {}).values()
                 for grid in setup.values()),
             "one-order-per-run",
             "Each Cell+Table rank's compute per interaction from the memory order of its own "
             "columns, since session 56 (sph records interactions and descents per column; "
             "predict multiplies a rank's compute by (a + b D_rank) / (a + b D_all), the line "
             "fitted on the long calibration dam breaks' later half): the disorder sits where "
             "the water moves (at 0.13 s of a 4-rank dam break the back rank read 0.21 descents "
             "per interaction, the front rank 0.40), and one profile for every rank had put the "
             "back rank, which sets the wall time, 6 % high in session 55's quiet jobs. Each "
             "Cell+List rank's too since session 57, read off Cell+Table's descents in the same "
             "columns at the same times (Cell+List's own stay at 0.86 per interaction whatever "
             "its memory order; its particles move and migrate as Cell+Table's do, and its cost "
             "per interaction follows Cell+Table's descents with R^2 0.92-0.96). A still tank's "
             "order barely moves: its lines are refused (model.json, by_column_unused). Built "
             "after seeing session 55's per-rank validation errors (Cell+List's after its 3-rank "
             "dam break came out +4.9 % over five quiet jobs): **tuned**. With every rank at the "
             "whole run's order (sessions 1-55, predict --rank-disorder none) on the same runs: "
             "{o} (one-order-per-run/validation.json)."),
            (bool((model.get("time_sharing_bubble") or {}).get("per_phi") is not None),
             "no-bubble",
             "A replayed time-shared step times 1 + k phi where every core time-shares two busy "
             "ranks (predict --time-sharing-bubble on, since session 80; phi: per core the second "
             "busiest rank's compute over the busiest's, the least over the cores; k from the "
             "calibration's own time-shared runs, each interval's measured step over the step "
             "replayed from its measured CPU). The replay fed a run's own CPU came out 0.5-2.5 % "
             "short where some core serves one busy rank, 10-16 % short where every core serves "
             "two (a scheduler trace: 12 % of the busiest core in 2 us yield-to-yield turns, "
             "both its ranks waiting for the other core). The form was chosen after the balanced "
             "4-rank table dam break came out -10 % over 22 blind jobs: **tuned** (k itself is "
             "fitted in each job). Without it (sessions 40-79) on the same runs: {o} "
             "(no-bubble/validation.json)."),
            (bool((model.get("untimed_per_step") or {}).get("layouts")),
             "no-untimed",
             "Every step also pays the wall time no phase timer holds (predict --untimed on, "
             "since session 94): the run's own bookkeeping between the timed phases, measured on "
             "each calibration run as its wall_s less the slowest rank's timers, per step, the "
             "median per ranks x threads (model.json untimed_per_step; 34-44 us a step on 2 "
             "ranks and 5-7 on 1 in session 94's jobs, 3-4 % of a half-scale Cell+Sorted run). "
             "Found by the model predicting its own calibration runs (in-sample/), not fitted "
             "to validation runs; adopted after replaying 34 jobs (the short Cell+Sorted "
             "configurations about a point higher, closer to their runs; the jobs' max -0.03 "
             "points, standard error 0.10): **tuned** as a choice. Without it (sessions 1-93) on "
             "the same runs: {o} (no-untimed/validation.json)."),
        ]
        not_compared = []
        for in_use, subdir, line in choices:
            o = untuned(subdir)
            if in_use and o:
                lines.append(line.format(o=o))
            elif in_use:
                not_compared.append(subdir)
        paths = [r["path"] for r in model["calibration_runs"]]
        if (any("_list_b" in p or "_table_b" in p for p in paths)
                and not any("dambreak_s0.5_list_b" in p or "dambreak_s0.5_table_b" in p
                            for p in paths)):
            # No comparison on this job's runs: the runs it would need are the ones not made.
            lines.append(
                "Cell+List's and Cell+Table's long dam breaks (scale 0.5, 1000 steps) in round a "
                "only, since session 90 (rounds a and b in sessions 46-89): 7 s of calibration "
                "less. Decided after replaying 81 stored main jobs of sessions 82-89 without round "
                "b's (scripts/replay-job.sh --exclude): the jobs' mean wall median / max 2.73 / "
                "10.52 -> 2.64 / 10.69 % (the max paired +0.17 points, standard error 0.16), both "
                "targets met in 44 -> 47 of 81, the calibration 27.5 -> 22.3 % of the validation "
                "runs' run time: **tuned**. The runs that would validate round b's beside are not "
                "made, so no untuned figure on this job's runs (model/NOTES.md, session 90).")
        # Candidates not in use, beside on the same runs.
        drift = untuned("run-drift")
        if drift:
            lines.append("A candidate not in use: each interval's compute at the host's speed "
                         "drift within a run at its time since the run's start (predict "
                         "--run-drift on, calibrate's speed_gauge.run_drift; model/NOTES.md, "
                         f"session 79) on the same runs: {drift} (run-drift/validation.json).")
        if not_compared:
            # The --quick job runs 5 of the 17 comparison models (scripts/model-node.sh).
            lines.append("Tuned choices in use without their comparison model in this job (no "
                         "validation.json in " + ", ".join(f"{d}/" for d in not_compared)
                         + "; `--quick` runs one comparison of each kind): their untuned "
                         "figures are not measured here.")
        repeated, cal_repeated = repeated_runs(args.dir, "val"), repeated_runs(args.dir, "cal")
        o = untuned("first-runs")
        if (repeated or cal_repeated) and o:
            text = ""
            if repeated:
                text += ("The shortest validation runs (under 3 s in the full job; since session 71 "
                         "also the Cell+List and Cell+Table still tanks, 4-6 s, after the list still "
                         "tank was a job's largest miss in four of seven jobs; since session 75 also the "
                         "Cell+Sorted dam breaks on 2 ranks, about 2.3 s, single runs before), run 3 times each "
                         "and the run with the median wall time validated (chosen in session 34 after "
                         "a 1.4 s run came out 11 % slower than its twin; the runs spread over the "
                         "job since session 42, back to back before): " + "; ".join(repeated)
                         + ". ")
            if cal_repeated:
                text += ("The calibration runs under 0.5 s likewise, the median run of each round "
                         "calibrating (chosen in session 36 after one 0.3 s still tank at 1.19 times "
                         "the fit put the sorted still tanks 13-17 % high): "
                         + "; ".join(cal_repeated) + ". ")
            lines.append(text + ("Calibrated and validated" if cal_repeated else "Validated")
                         + f" with each one's first run instead: {o} (first-runs/validation.json).")
    if s["inline_comm_abs_error_per_interval"]:
        replayed = s.get("inline_comm_abs_error_per_interval_exchange_benchmark") is not None
        above = ("; above the cores the step replayed from each rank's measured CPU time before "
                 "each shift (sph --replay-slice-ms, 1.5 ms)" if replayed else "")
        lines.append(f"Communication, inline prediction (within the cores the exchange benchmark, the "
                     f"mean shift cost at the measured gap; {fresh_source(args)}{above}): median "
                     f"per-interval |error| "
                     f"{100 * s['inline_comm_abs_error_per_interval']['median']:.1f} % (target 20 %); "
                     f"{inline_by_load(validation)}.")
        bench = s.get("inline_comm_abs_error_per_interval_exchange_benchmark")
        if bench:
            lines.append(f"Above the cores the inline prediction replays the time-shared step (who runs "
                         f"while whom waits, model/NOTES.md), with the slice of the model's replay, "
                         f"1.5 ms, preferred to the 4 ms tick in session 39 after seeing sessions 38-39's "
                         f"runs (**tuned**); chosen in session 40 after the exchange benchmark (every rank "
                         f"the same work) missed the parked rank in every main job. Untuned, the exchange "
                         f"benchmark above the cores as well (the inline prediction before, recorded by the "
                         f"same runs): median per-interval |error| {100 * bench['median']:.1f} %; "
                         f"{inline_by_load(validation, 'inline_exchange_error')}.")
        own = s.get("inline_comm_abs_error_per_interval_own_kind_gap")
        if own:
            lines.append(f"Within the cores the migration and the density refresh are costed at the gap since "
                         f"the shift before of any kind, a rule chosen in session 32 after seeing session 31's "
                         f"migration errors (**tuned**; model/NOTES.md, \"Which gap, again\"). Untuned, at the "
                         f"gap since their own kind (the rule before, recorded by the same runs): median "
                         f"per-interval |error| {100 * own['median']:.1f} %; {inline_by_load(validation, 'inline_own_kind_gap_error')}.")
        by_exchange = inline_by_exchange(validation)
        if by_exchange:
            lines.append(by_exchange)
        drift = exchange_drift(os.path.join(args.dir, "exchange-fresh"), model)
        if drift:
            lines.append(drift)
    same, other = (s.get("inline_comm_abs_error_per_interval_" + k) for k in ("profile_mode", "other_mode"))
    if same or other:
        part = lambda x: (f"median {100 * x['median']:.1f} % over {x['count']} intervals" if x
                          else "no interval")
        lines.append(f"Latency mode (sph --machine within the cores probes 64 back-to-back 64-byte shifts "
                     f"every interval; this VM flips between about 0.4 and 1.0 us as the hypervisor moves "
                     f"the virtual cores): intervals in the mode the exchange benchmark ran in (probe "
                     f"0.89-2.2x its figure: the app's probe reads 1.4x the benchmark's in the same mode) "
                     f"{part(same)}; in the other mode {part(other)}. "
                     f"Time-shared runs do not probe.")
    if s.get("inline_hockney_comm_abs_error_per_interval"):
        lines.append(f"Communication, inline ping-pong Hockney alone (the thesis' T_COMM_PREDICT): "
                     f"median per-interval |error| "
                     f"{100 * s['inline_hockney_comm_abs_error_per_interval']['median']:.1f} %.")
    if s["model_comm_abs_error_per_interval"]:
        lines.append(f"Communication, model prediction from the predicted workload: median per-interval "
                     f"|error| {100 * s['model_comm_abs_error_per_interval']['median']:.1f} %.")
    per_step = os.path.join(args.dir, "per-step-overhead", "validation.json")
    if replaying and os.path.exists(per_step):
        tick = os.path.join(args.dir, "time-shared-replay-4ms", "validation.json")
        lines.append(replay_in_use_line(validation, load(per_step),
                                        load(tick) if os.path.exists(tick) else None))
    # sph --overlap beside its blocking twin: the exchanges' exposed time, measured in both.
    for r in validation["configurations"]:
        if not r.get("overlap"):
            continue
        twin = next((b for b in validation["configurations"] if not b.get("overlap") and
                     all(b[k] == r[k] for k in ("setup", "grid", "scale", "ranks", "threads", "steps"))
                     and b.get("decomposition") == r.get("decomposition")), None)
        c = r["phases"]["comm"]
        text = (f"Overlap, {r['setup']} {r['grid']} s{r['scale']:g} {r['ranks']} x {r['threads']}: "
                f"exposed communication {1e3 * c['measured_s']:.2f} ms (all ranks), predicted "
                f"{1e3 * c['predicted_s']:.2f} ms by the model and {1e3 * c.get('inline_s', 0):.2f} ms "
                f"inline; compute behind the transfers {c.get('overlap_window_s', 0):.2f} s, hiding "
                f"{1e3 * c.get('hidden_inline_s', 0):.2f} ms of predicted transfer (T_overlap, inline)")
        if twin:
            b = twin["phases"]["comm"]["measured_s"]
            hb = twin["phases"]["comm"].get("halo_measured_s", 0)
            ho = c.get("halo_measured_s", 0)
            if hb > 0:
                text += (f"; ghost and density exchanges {1e3 * ho:.2f} ms against "
                         f"{1e3 * hb:.2f} ms in the blocking run: {100 * (1 - ho / hb):.0f} % hidden")
            if b > 0:
                text += (f"; all three exchanges {100 * (1 - c['measured_s'] / b):.0f} % "
                         f"(migration stays blocking)")
        lines.append(text + ".")
    if s.get("peak_rss_abs_error"):
        m = validation["configurations"][0].get("peak_rss_bytes", {})
        lines.append(f"Peak RSS of the largest rank (memory model of model/NOTES.md): |error| median "
                     f"{100 * s['peak_rss_abs_error']['median']:.1f} %, max "
                     f"{100 * s['peak_rss_abs_error']['max']:.1f} %; the thesis' Eqs. 4.4/4.5 bound is "
                     f"{m.get('thesis_bound_max_rank', 0) / max(m.get('measured_max_rank', 1), 1):.1f}x the "
                     f"measured peak in the first configuration.")
    within, shared = s.get("compute_per_busy_rank_abs_error"), s.get("compute_per_busy_rank_abs_error_time_shared")
    if within or shared:
        parts = [f"{where}: median {100 * x['median']:.1f} %, max {100 * x['max']:.1f} % over {x['count']} ranks"
                 for where, x in (("within the cores", within), ("time-shared", shared)) if x]
        text = ("Compute of each busy rank (a tenth or more of its run's) of the multi-rank runs, |error| "
                "(how the model shares the work and its cost between the ranks, which the sum hides; a "
                "time-shared rank's timers also hold the time its core ran another rank): "
                + "; ".join(parts))
        flat = os.path.join(args.dir, "one-order-per-run", "validation.json")
        if os.path.exists(flat):
            fs = load(flat)["summary"]
            fw, fsh = fs.get("compute_per_busy_rank_abs_error"), fs.get("compute_per_busy_rank_abs_error_time_shared")
            fparts = [f"{100 * x['median']:.1f} / {100 * x['max']:.1f} %" for x in (fw, fsh) if x]
            text += (". With every rank at the whole run's memory order (one-order-per-run/): "
                     + " and ".join(fparts))
        lines.append(text + ".")
    # The same at each rank's own core's speed (session 77): the host's speed out, rank by rank.
    own = [(w, s.get(k)) for w, k in (("within the cores", "compute_per_busy_rank_at_own_speed"),
                                      ("time-shared", "compute_per_busy_rank_at_own_speed_time_shared"))
           if s.get(k)]
    if own:
        lines.append("The same at each rank's own core's speed (the prediction times the rank's own "
                     "speed gauge over the reference, so the two vCPUs' speeds are out; on a shared "
                     "core a gauge sample may hold the other rank's turn): "
                     + "; ".join(f"{w}: error median {100 * x['median_error']:+.1f} %, |error| median "
                                 f"{100 * x['median_abs_error']:.1f} %, max {100 * x['max_abs_error']:.1f} % "
                                 f"over {x['count']} ranks" for w, x in own)
                     + " (per rank over jobs: scripts/model-bias.py --term rank-compute).")
    lines += in_sample_lines(args.dir)
    # The workload term alone (session 57): each busy rank-interval's field particles as the
    # re-cut trace gave them against the run's.
    if s.get("field_per_busy_rank_interval"):
        x = s["field_per_busy_rank_interval"]
        lines.append("Workload of each busy rank-interval (field particles: the calibration trace's "
                     "columns at the same Froude time, stretched onto the run's and re-cut into its "
                     f"slabs, against the run's mean): error median {100 * x['median_error']:+.1f} %, "
                     f"|error| median {100 * x['median_abs_error']:.1f} %, max "
                     f"{100 * x['max_abs_error']:.1f} % over {x['count']} (the Froude similarity "
                     "and the re-cut alone).")
    # The memory-order term alone (session 57): each busy rank-interval's descents per
    # interaction as predicted (its columns' in the calibration run at the same Froude time)
    # against the run's own count.
    order = [(w, s.get(k)) for w, k in (("equal slabs", "descents_per_interaction_per_busy_rank_interval"),
                                        ("balanced slabs", "descents_per_interaction_per_busy_rank_interval_balanced"))
             if s.get(k)]
    if order:
        simulated = any(
            (json.load(open(p)).get("model_source") or {}).get("memory_order_time") == "simulated"
            for p in glob.glob(os.path.join(args.dir, "prediction_*.json")))
        carried = ("with its columns at the same Froude time, each equal slab's then carried to "
                   "the whole water's order at the run's simulated time (predict "
                   "--memory-order-time simulated, session 59)" if simulated else
                   "from the calibration run at the same Froude time")
        lines.append("Memory order of each busy rank-interval (Cell+Table's descents per interaction of "
                     f"its columns, as the model carried them {carried}, against the run's count; "
                     "the term the per-rank cost reads): "
                     + "; ".join(f"{w}: error median {100 * x['median_error']:+.1f} %, |error| median "
                                 f"{100 * x['median_abs_error']:.1f} %, max {100 * x['max_abs_error']:.1f} % "
                                 f"over {x['count']}" for w, x in order)
                     + ". The order decays with simulated time, not Froude time (model/NOTES.md, "
                     "sessions 57 and 59)"
                     + ("" if simulated else ", so a scale-1 run reads more than its half-scale "
                        "calibration carried")
                     + ", and a balanced run's front rank, whose particles its re-cuts refile "
                     "(which no calibration run does), reads far less than carried.")
    # The cost term alone (session 73): each busy rank-interval's compute per interaction, the
    # prediction at the run's own speed, within the cores; its first and last thirds apart show
    # whether the cost's course through a run (the Froude-time profile, the memory order's carry)
    # follows the run's.
    cost = s.get("cost_per_interaction_per_busy_rank_interval")
    if cost:
        def third(key):
            x = s.get(f"cost_per_interaction_per_busy_rank_interval_{key}")
            return f"{100 * x['median_error']:+.1f} %" if x else "none"
        by_grid = {}
        for c in validation["configurations"]:
            cp = c.get("cost_per_interaction")
            if cp and cp.get("first_third") and cp.get("last_third"):
                by_grid.setdefault(c["grid"], []).append(
                    (cp["first_third"]["median_error"], cp["last_third"]["median_error"]))
        grids = "; ".join(
            f"{g} {100 * statistics.median(f for f, _ in e):+.1f} -> "
            f"{100 * statistics.median(l for _, l in e):+.1f} %"
            for g, e in sorted(by_grid.items()))
        lines.append("Cost per interaction of each busy rank-interval within the cores (compute over "
                     "interactions, the prediction at the run's own speed against the run's; the "
                     "compute term apart from the work it prices): error median "
                     f"{100 * cost['median_error']:+.1f} %, |error| median "
                     f"{100 * cost['median_abs_error']:.1f} %, max {100 * cost['max_abs_error']:.1f} % "
                     f"over {cost['count']}; first third of the runs {third('first_third')}, last "
                     f"third {third('last_third')}"
                     + (f" (per grid, the configurations' median first third -> last third: {grids})"
                        if grids else "")
                     + ". A last third above the first: the cost is predicted to rise through the "
                     "run more than it does (model/NOTES.md, session 73).")
    lines.append("")
    lines.append(f"Roofline: {model['roofline']['verdict']}.")
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")


def shared_errors(v):
    """Wall |error| of the configurations above the cores and the model's per-interval comm error
    over their intervals."""
    confs = [c for c in v["configurations"] if c.get("oversubscribed")]
    walls = sorted(abs(c["wall_error"]) for c in confs)
    comm = sorted(abs(e["model_error"]) for c in confs for e in c["comm_series"]
                  if e.get("model_error") is not None)
    return walls, comm


def replay_in_use_line(validation, per_step, tick=None):
    """The model in use replays the time-shared step (session 40): beside it the per-step overhead
    (sessions 34-39's model, per-step-overhead/) and the replay at the 4 ms tick."""
    def med(v):
        return statistics.median(v) if v else float("nan")

    def top(v):
        return max(v, default=float("nan"))

    (w, c), (pw, pc) = shared_errors(validation), shared_errors(per_step)
    a = per_step["summary"]["wall_abs_error"]
    text = (f"Time-shared step replayed (predict --time-sharing-overhead replay, the model in use since "
            f"session 40: who runs while whom waits, the step, transfers and waits of one-thread ranks on "
            f"one node above the cores, no overhead added; slice 1.5 ms, the kernel's EEVDF base slice, "
            f"preferred to the 4 ms tick in session 39 after seeing sessions 38-39's runs: **tuned**; "
            f"the replay made the default after session 40's three main jobs, where it matched the "
            f"per-step overhead on wall time and halved the model's time-shared communication error): "
            f"over the {len(w)} time-shared configurations wall |error| median {100 * med(w):.1f} %, max "
            f"{100 * top(w):.1f} %; communication, model prediction, median per-interval |error| "
            f"{100 * med(c):.1f} % over {len(c)} time-shared intervals. With the per-step overhead "
            f"instead (sessions 34-39's model) on the same runs: time-shared wall |error| median "
            f"{100 * med(pw):.1f} %, max {100 * top(pw):.1f} %; communication {100 * med(pc):.1f} %; all "
            f"{a['count']} configurations: median {100 * a['median']:.1f} %, max {100 * a['max']:.1f} % "
            f"(per-step-overhead/validation.json).")
    if tick is not None:
        tw, tc = shared_errors(tick)
        text += (f" Untuned, the replay at the 4 ms tick: time-shared wall |error| median "
                 f"{100 * med(tw):.1f} %, max {100 * top(tw):.1f} %; communication {100 * med(tc):.1f} % "
                 f"(time-shared-replay-4ms/validation.json).")
    return text


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dir", required=True, help="results folder holding model.json etc.")
    ap.add_argument("--calibration-s", type=float, default=0.0, help="wall time of calibration runs (s)")
    ap.add_argument("--validation-s", type=float, default=0.0, help="wall time of validation runs (s)")
    ap.add_argument("--quick", action="store_true",
                    help="the job ran with --quick (smoke sizes): validation.md says its figures mean nothing")
    ap.add_argument("--fresh-exchange-s", type=float, default=0.0,
                    help="wall time of the exchange benchmarks run before the validation runs (s)")
    args = ap.parse_args()
    d = args.dir
    try:
        model = load(os.path.join(d, "model.json"))
        validation = load(os.path.join(d, "validation.json"))
        predictions = [load(p) for p in sorted(glob.glob(os.path.join(d, "prediction_*.json")))]
    except (OSError, json.JSONDecodeError) as e:
        print(f"plot-model.py: error: {e}", file=sys.stderr)
        return 2
    runs = os.path.join(d, "runs")
    roofline(model, os.path.join(d, "roofline.png"))
    scaling(predictions, validation, os.path.join(d, "scaling.png"))
    workload(model, predictions, runs, os.path.join(d, "workload.png"))
    regressions(model, runs, os.path.join(d, "regressions.png"))
    comm_error(validation, os.path.join(d, "comm_error.png"))
    markdown(model, validation, args, os.path.join(d, "validation.md"))
    print(f"plots and validation.md written to {d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
