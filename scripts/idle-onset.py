#!/usr/bin/python3
"""Idle onset of the dam break (thesis 3.7.3, Fig. 4.4 and Eq. 4.1): the first step at which
every one of P equal slabs holds a fluid particle, per scale, measured, predicted by the model
and by the thesis' law c_P 1.3^s.

    /usr/bin/python3 scripts/idle-onset.py [--scales 1,2,3] [--predict-scales 1,2,3,4]
        [--slabs 2,4,8] [--calibration-scale 0.5] [--check-ranks 8] [--threads 2]
        [--machine results/<host>/machine.json] [--out results/<host>/idle_onset.json]

Measured: 1-rank dam breaks (Cell+Sorted, report every 10 steps) at each scale; the slabs'
field counts come from the run's column histograms cut as the app cuts (sph::equal_cuts:
rank r starts at column floor(r C / P)). The app's trajectory is bitwise the same at any rank
count (tests/integration), so these are the P-rank run's counts; --check-ranks P runs one real
P-rank dam break at the first scale and compares its ranks' own counts.
Predicted: `sphmodel calibrate` on one half-scale run (the workload trace, Froude-rescaled) plus
the main job's calibration runs (results/<host>/runs/cal_*.json, for the cost terms predict
needs), then `sphmodel predict` per scale; its first_step_busy_per_rank.
Thesis: Eq. 4.1 with c_P fitted to the measured onsets (least squares in log), beside the
growth per scale increment it implies, and the Froude law onset(s) = onset(s0) sqrt(s / s0)
(lengths x s, times x sqrt(s), dt fixed). Onset steps are not timings: the script may run
beside other work.
"""
import argparse
import glob
import json
import math
import os
import socket
import subprocess
import sys
import tempfile

from script_common import git_commit, pyplot, write_json

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(os.environ.get("SPHPERF_BUILD_DIR", os.path.join(ROOT, "build")), "bin")
INTERVAL = 10  # report steps: the measured onset's resolution


def fail(msg):
    print(f"idle-onset: {msg}", file=sys.stderr)
    sys.exit(2)


def parse_list(text, kind, name, minimum):
    try:
        values = [kind(v) for v in text.split(",") if v]
    except ValueError:
        fail(f"--{name} '{text}': expected a comma-separated list of numbers")
    if not values or any(not math.isfinite(v) or v < minimum for v in values):
        fail(f"--{name} '{text}': every value must be >= {minimum}")
    return values


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        last = r.stderr.strip().splitlines()
        fail(f"{' '.join(cmd)} failed: {last[-1] if last else f'exit {r.returncode}'}")
    return r.stdout


def run_sph(scale, end_time, ranks, threads, report):
    print(f"  sph dam break scale {scale}, {ranks} rank(s) x {threads}, to t = {end_time:.3f} s",
          flush=True)
    run(["bash", os.path.join(ROOT, "scripts", "mpirun.sh"), "-n", str(ranks), "-t", str(threads),
         os.path.join(BIN, "sph"), "--quiet", "--setup", "dambreak", "--grid", "sorted",
         "--scale", str(scale), "--threads", str(threads), "--end-time", f"{end_time:.4f}",
         "--interval", str(INTERVAL), "--report", report])
    return json.load(open(report))


def equal_cuts(slabs, columns):
    return [r * columns // slabs for r in range(slabs + 1)]


def onset_from_columns(report, slabs):
    """First report step at which each slab holds a fluid particle (None: not in the run)."""
    columns = report["config"]["cell_columns"]
    cuts = equal_cuts(slabs, columns)
    # Step 0 from the initial histogram; then the end of the first interval that has water.
    first = [0 if sum(report["initial_columns"][cuts[r]:cuts[r + 1]]) >= 1 else None
             for r in range(slabs)]
    for iv in report["intervals"]:
        for r in range(slabs):
            if first[r] is None and sum(iv["columns"][cuts[r]:cuts[r + 1]]) >= 1:
                first[r] = iv["step"]
    return first


def onset_from_ranks(report):
    """The same from a P-rank run's own per-rank field counts."""
    ranks = report["config"]["ranks"]
    cuts = equal_cuts(ranks, report["config"]["cell_columns"])
    first = [0 if sum(report["initial_columns"][cuts[r]:cuts[r + 1]]) >= 1 else None
             for r in range(ranks)]
    for iv in report["intervals"]:
        for r, rank in enumerate(iv["ranks"]):
            if first[r] is None and rank["field"] >= 1:
                first[r] = iv["step"]
    return first


def all_busy(first):
    return None if any(f is None for f in first) else max(first)


def fit_thesis(points):
    """Eq. 4.1, onset = c 1.3^s: c by least squares in log; and the free growth g of c g^s."""
    if not points:
        return None
    logc = sum(math.log(n) - s * math.log(1.3) for s, n in points) / len(points)
    out = {"c_steps": math.exp(logc)}
    if len(points) >= 2:
        ms = sum(s for s, _ in points) / len(points)
        ml = sum(math.log(n) for _, n in points) / len(points)
        sxx = sum((s - ms) ** 2 for s, _ in points)
        slope = sum((s - ms) * (math.log(n) - ml) for s, n in points) / sxx
        out["growth_per_scale_increment"] = math.exp(slope)
        # The power law onset ~ s^b (Froude: b = 1/2 at fixed dt).
        mx = sum(math.log(s) for s, _ in points) / len(points)
        sxx = sum((math.log(s) - mx) ** 2 for s, _ in points)
        out["power_law_exponent"] = sum((math.log(s) - mx) * (math.log(n) - ml)
                                        for s, n in points) / sxx
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scales", default="1,2,3", help="measured scales, default 1,2,3")
    ap.add_argument("--predict-scales", default="1,2,3,4", help="default 1,2,3,4")
    ap.add_argument("--slabs", default="2,4,8", help="rank counts (equal slabs), default 2,4,8")
    ap.add_argument("--calibration-scale", type=float, default=0.5, help="default 0.5")
    ap.add_argument("--check-ranks", type=int, default=8,
                    help="one real run at this rank count at the first scale (0: none), default 8")
    ap.add_argument("--threads", type=int, default=2, help="threads of the 1-rank runs, default 2")
    ap.add_argument("--machine", help="machine.json (default results/<host>/machine.json)")
    ap.add_argument("--calibration-runs", help="glob of the cost-term calibration reports "
                    "(default results/<host>/runs/cal_*.json)")
    ap.add_argument("--runs-dir", help="where the runs are kept (default results/<host>/idle_onset)")
    ap.add_argument("--reuse", action="store_true", help="reuse reports already in --runs-dir")
    ap.add_argument("--out", help="JSON output (default results/<host>/idle_onset.json)")
    ap.add_argument("--png", help="plot (default: the JSON's path with .png)")
    a = ap.parse_args()
    scales = parse_list(a.scales, float, "scales", 1e-3)
    predict_scales = parse_list(a.predict_scales, float, "predict-scales", 1e-3)
    slabs = [int(p) for p in parse_list(a.slabs, int, "slabs", 2)]
    if not (a.calibration_scale > 0 and math.isfinite(a.calibration_scale)):
        fail(f"--calibration-scale {a.calibration_scale}: expected a finite value > 0")
    if a.threads < 1 or a.check_ranks < 0:
        fail("--threads must be >= 1 and --check-ranks >= 0")
    host = socket.gethostname()
    res = os.path.join(ROOT, "results", host)
    machine = a.machine or os.path.join(res, "machine.json")
    cal_glob = a.calibration_runs or os.path.join(res, "runs", "cal_*.json")
    cal_runs = sorted(glob.glob(cal_glob))
    out = a.out or os.path.join(res, "idle_onset.json")
    png = a.png or os.path.splitext(out)[0] + ".png"
    runs_dir = a.runs_dir or os.path.join(res, "idle_onset")
    for exe in ("sph", "sphmodel"):
        if not os.path.exists(os.path.join(BIN, exe)):
            fail(f"{BIN}/{exe} missing; run scripts/build.sh first")
    if not os.path.exists(machine):
        fail(f"{machine} missing; run scripts/characterise-node.sh first (or pass --machine)")
    if not cal_runs:
        fail(f"no calibration reports match {cal_glob}; run the main job first")
    os.makedirs(runs_dir, exist_ok=True)

    def report(scale, ranks, threads, end_time):
        path = os.path.join(runs_dir, f"dambreak_s{scale:g}_r{ranks}.json")
        if a.reuse and os.path.exists(path):
            rep = json.load(open(path))
            if rep["intervals"][-1]["time_s"] >= end_time - 1e-9:
                return rep
        return run_sph(scale, end_time, ranks, threads, path)

    # The half-scale trace, long enough for the furthest slab at the largest scale by Froude
    # (its own 8-slab onset, carried to the largest scale, plus a margin).
    s0 = a.calibration_scale
    tank_time = 0.7 * math.sqrt(s0 / 0.5)  # the front reaches the far wall by then
    cal = report(s0, 1, a.threads, tank_time)
    last = all_busy(onset_from_columns(cal, max(slabs)))
    if last is None:
        fail(f"the scale-{s0:g} run never fills {max(slabs)} slabs by t = {tank_time:.2f} s")
    # Runs and predictions reach the half-scale onset carried by Froude, plus 5 %: measured
    # onsets grow slower than sqrt(s), so that suffices (an onset not reached is reported).
    t_last = 1.05 * last * cal["config"]["dt"]
    print(f"measured: 1-rank runs at scales {', '.join(f'{s:g}' for s in scales)}", flush=True)
    measured = {}
    for s in scales:
        rep = report(s, 1, a.threads, t_last * math.sqrt(s / s0))
        measured[s] = {"report": os.path.relpath(os.path.join(runs_dir, f"dambreak_s{s:g}_r1.json"), ROOT),
                       "fluid_particles": rep["config"]["fluid_particles"],
                       "end_step": rep["intervals"][-1]["step"],
                       "slabs": {str(P): onset_from_columns(rep, P) for P in slabs}}
        if s == scales[0]:
            first_report = rep
    check = None
    if a.check_ranks:
        P = a.check_ranks
        s = scales[0]
        want = all_busy(measured[s]["slabs"].get(str(P)) or onset_from_columns(first_report, P))
        if want is None:
            fail(f"the {P}-slab onset at scale {s:g} is beyond the 1-rank run")
        rep = report(s, P, 1, (want + 5 * INTERVAL) * first_report["config"]["dt"])
        own = onset_from_ranks(rep)
        hist = onset_from_columns(first_report, P)
        check = {"scale": s, "ranks": P, "first_busy_step_per_rank_own_counts": own,
                 "first_busy_step_per_rank_from_1_rank_histogram": hist, "equal": own == hist}
        print(f"  {P}-rank run's own onsets {own}; from the 1-rank histogram {hist}: "
              f"{'equal' if own == hist else 'DIFFERENT'}", flush=True)

    # The model: the half-scale trace plus the main job's cost runs, then predict per scale.
    with tempfile.TemporaryDirectory() as tmp:
        model = os.path.join(tmp, "model.json")
        run([os.path.join(BIN, "sphmodel"), "calibrate", "--machine", machine, "--runs",
             *cal_runs, os.path.join(runs_dir, f"dambreak_s{s0:g}_r1.json"), "--out", model])
        trace = json.load(open(model))["traces"]["dambreak"]
        if abs(trace["scale"] - s0) > 1e-12:
            fail(f"the model kept the trace of {trace['source']}, not the scale-{s0:g} run")
        predicted = {}
        for s in predict_scales:
            end = t_last * math.sqrt(s / s0)
            pred = os.path.join(tmp, "pred.json")
            run([os.path.join(BIN, "sphmodel"), "predict", "--model", model, "--setup",
                 "dambreak", "--grid", "sorted", "--scale", f"{s:g}", "--threads", "1",
                 "--ranks", ",".join(map(str, slabs)), "--end-time", f"{end:.4f}", "--out", pred])
            p = json.load(open(pred))
            predicted[s] = {"fluid_particles": p["fluid_particles"],
                            "end_step": p["request"]["steps"],
                            "slabs": {str(c["ranks"]): c["first_step_busy_per_rank"]
                                      for c in p["configurations"]},
                            "idle_fraction": {str(c["ranks"]): c["idle_fraction"]
                                              for c in p["configurations"]}}

    rows = []
    for P in slabs:
        pts = [(s, all_busy(measured[s]["slabs"][str(P)])) for s in scales]
        pts = [(s, n) for s, n in pts if n]
        thesis = fit_thesis(pts)
        ref_s, ref_n = pts[0] if pts else (None, None)
        for s in sorted(set(scales) | set(predict_scales)):
            m = all_busy(measured[s]["slabs"][str(P)]) if s in measured else None
            pr = all_busy(predicted[s]["slabs"][str(P)]) if s in predicted else None
            row = {"slabs": P, "scale": s, "measured_step": m, "predicted_step": pr,
                   "predicted_error": (pr - m) / m if m and pr is not None else None,
                   "thesis_law_step": thesis["c_steps"] * 1.3 ** s if thesis else None,
                   "froude_law_step": ref_n * math.sqrt(s / ref_s) if ref_n else None}
            rows.append(row)
    fits = {str(P): fit_thesis([(s, all_busy(measured[s]["slabs"][str(P)])) for s in scales
                                if all_busy(measured[s]["slabs"][str(P)])]) for P in slabs}

    print(f"{'slabs':>5} {'scale':>5} {'measured':>9} {'model':>8} {'error':>7} "
          f"{'c 1.3^s':>8} {'Froude':>8}")
    for r in rows:
        f = lambda v, w=8: f"{v:{w}.0f}" if v is not None else f"{'-':>{w}}"
        err = f"{100 * r['predicted_error']:+6.1f}%" if r["predicted_error"] is not None else f"{'-':>7}"
        print(f"{r['slabs']:5d} {r['scale']:5g} {f(r['measured_step'], 9)} {f(r['predicted_step'])} "
              f"{err} {f(r['thesis_law_step'])} {f(r['froude_law_step'])}")
    for P, fit in fits.items():
        if fit and "growth_per_scale_increment" in fit:
            print(f"{P} slabs: measured growth per scale increment {fit['growth_per_scale_increment']:.3f} "
                  f"(thesis 1.3), onset ~ s^{fit['power_law_exponent']:.3f} (Froude 0.5)")

    commit = git_commit(ROOT)
    doc = {"schema": 1, "benchmark": "idle_onset", "host": host, "git_commit": commit,
           "build": first_report.get("build"), "topology": first_report.get("topology"),
           "grid": "sorted", "report_interval_steps": INTERVAL,
           "dt_s": first_report["config"]["dt"], "calibration_scale": s0,
           "calibration_report": os.path.relpath(os.path.join(runs_dir, f"dambreak_s{s0:g}_r1.json"), ROOT),
           "measured": {f"{s:g}": v for s, v in measured.items()},
           "predicted": {f"{s:g}": v for s, v in predicted.items()},
           "rank_check": check, "thesis_law_fits": fits, "rows": rows}
    write_json(out, doc)
    plot(doc, slabs, png)


def plot(doc, slabs, png):
    plt = pyplot("idle-onset")
    if plt is None:
        return
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.8))
    colours = dict(zip(slabs, ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"]))
    for P in slabs:
        rs = [r for r in doc["rows"] if r["slabs"] == P]
        c = colours[P]
        ms = [(r["scale"], r["measured_step"]) for r in rs if r["measured_step"]]
        ps = [(r["scale"], r["predicted_step"]) for r in rs if r["predicted_step"] is not None]
        ts = [(r["scale"], r["thesis_law_step"]) for r in rs if r["thesis_law_step"]]
        fs = [(r["scale"], r["froude_law_step"]) for r in rs if r["froude_law_step"]]
        if ms:
            ax.plot(*zip(*ms), "o", color=c, ms=7, label=f"{P} ranks measured")
        if ps:
            ax.plot(*zip(*ps), "-", color=c, label=f"{P} ranks model (half-scale trace)")
        if ts:
            ax.plot(*zip(*ts), "--", color=c, alpha=0.7, label=f"{P} ranks thesis c 1.3^s")
        if fs:
            ax.plot(*zip(*fs), ":", color=c, alpha=0.7, label=f"{P} ranks Froude sqrt(s)")
    ax.set_xlabel("scale s")
    ax.set_ylabel("first step with every rank busy")
    ax.set_title("Idle onset (thesis Fig. 4.4 left, Eq. 4.1)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    # The staircase: ranks with work against the step, largest slab count, per measured scale.
    P = max(slabs)
    for s, m in doc["measured"].items():
        first = sorted(f for f in m["slabs"][str(P)] if f is not None)
        steps = [0] + first + [m["end_step"]]
        busy = [sum(1 for f in first if f <= x) / P for x in steps]
        ax2.step(steps, [1 - b for b in busy], where="post", label=f"scale {s} measured")
        if s in doc["predicted"]:
            pf = sorted(f for f in doc["predicted"][s]["slabs"][str(P)] if f is not None)
            psteps = [0] + pf + [doc["predicted"][s]["end_step"]]
            pbusy = [sum(1 for f in pf if f <= x) / P for x in psteps]
            ax2.step(psteps, [1 - b for b in pbusy], where="post", linestyle="--",
                     label=f"scale {s} model")
    ax2.set_xlabel("step")
    ax2.set_ylabel(f"fraction of the {P} ranks idle")
    ax2.set_title("Staircase (thesis Fig. 4.4): a rank stops idling when the water arrives")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    print(f"written {png}")


if __name__ == "__main__":
    main()
