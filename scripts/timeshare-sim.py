#!/usr/bin/env python3
"""Replays a time-shared sph run through a model of who runs while whom waits (a prototype).

    scripts/timeshare-sim.py REPORT [--prediction PRED --shares-from RUN [RUN ...]]
                             [--slice-ms 1.5] [--cores 2] [--steps 20]

Each interval of REPORT (an sph report of a run with more ranks than cores) is replayed for
--steps steps: ranks bound round-robin to --cores cores (as scripts/mpirun.sh binds them), each
step three segments of CPU work, each followed by its shift as the app makes it (a zero-byte
handshake east then west, timed as wait; counts and payloads east then west, timed as comm).
A computing rank keeps its core until its segment ends or --slice-ms expires; a rank in MPI
polls, and yields its core while the message it needs has not arrived (mpi_yield_when_idle).
Sends complete at once (eager); a receive completes once the message is there and its rank
holds a core. Work per segment: by default the report's own timers per rank (compute phases
split 0.44 / 0.56 between continuity and momentum, as model/README.md counts their
operations); with --prediction, the predicted compute of the matching configuration split by
the segment shares of the busy ranks of --shares-from (calibration runs within the cores).
Prints, per interval and summed over ranks, simulated against measured wait and comm per step,
and the median per-interval comm error. Not part of the main job: model/README.md (session 39)
says what it reproduces and what not.
"""
import argparse
import json
import os
import statistics
import sys

TICK_S = 5e-6
CONTINUITY_SHARE = 0.44  # of the compute phase: continuity's operations against momentum's
SHIFTS = ("migration", "ghosts", "densities")


def fail(msg):
    print(f"timeshare-sim: {msg}", file=sys.stderr)
    sys.exit(2)


def load(path, kind):
    try:
        with open(path) as f:
            d = json.load(f)
    except (OSError, ValueError) as e:
        fail(f"{path}: {e}")
    if d.get("benchmark") != kind:
        fail(f"{path}: not a report of kind \"{kind}\" (benchmark: {d.get('benchmark')!r})")
    return d


def program(rank, ranks):
    """The ops of one step: per segment a compute op, then its shift's Sendrecv pairs."""
    west = rank - 1 if rank > 0 else None
    east = rank + 1 if rank < ranks - 1 else None
    ops = []
    for k, shift in enumerate(SHIFTS):
        ops.append(("compute", k))
        ops += [("sr", "wait", shift, east, west), ("sr", "wait", shift, west, east)]
        ops += [("sr", "comm", shift, east, west)] * 2 + [("sr", "comm", shift, west, east)] * 2
    return ops


def simulate(seg, cores, slice_s, steps, warm=2):
    """seg[r]: CPU seconds of rank r per step before its migration, ghost and density shifts."""
    ranks = len(seg)
    progs = [program(r, ranks) for r in range(ranks)]
    on_core = [[r for r in range(ranks) if r % cores == c] for c in range(cores)]
    running = [rs[0] if rs else None for rs in on_core]
    used_slice = [0.0] * cores
    pc, step, left, posted = [0] * ranks, [0] * ranks, [None] * ranks, [False] * ranks
    sent, got = {}, {}
    acc = [dict.fromkeys(("compute", "wait", "comm"), 0.0) for _ in range(ranks)]
    t, t_start = 0.0, None

    def run(r, budget):  # CPU for rank r; returns True if it yields its core
        spent = 0.0
        while step[r] < steps:
            op = progs[r][pc[r]]
            if op[0] == "compute":
                if left[r] is None:
                    left[r] = seg[r][op[1]]
                take = min(left[r], budget - spent)
                left[r] -= take
                spent += take
                if left[r] > 1e-12:
                    return False
                left[r] = None
            else:
                _, _, _, to, frm = op
                if not posted[r]:
                    if to is not None:
                        sent[(r, to)] = sent.get((r, to), 0) + 1
                    posted[r] = True
                if frm is not None:
                    if got.get((frm, r), 0) >= sent.get((frm, r), 0):
                        return True
                    got[(frm, r)] = got.get((frm, r), 0) + 1
                posted[r] = False
            pc[r] = (pc[r] + 1) % len(progs[r])
            step[r] += pc[r] == 0
            if spent >= budget:
                return False
        return True

    while min(step) < steps:
        for c in range(cores):
            r = running[c]
            if r is None:
                continue
            yielded = run(r, TICK_S)
            used_slice[c] += TICK_S
            if len(on_core[c]) > 1 and (yielded or used_slice[c] >= slice_s):
                running[c] = on_core[c][(on_core[c].index(r) + 1) % len(on_core[c])]
                used_slice[c] = 0.0
        t += TICK_S
        if t_start is None and min(step) >= warm:
            t_start = t
            acc = [dict.fromkeys(a, 0.0) for a in acc]
        for r in range(ranks):
            if step[r] < steps:
                op = progs[r][pc[r]]
                acc[r]["compute" if op[0] == "compute" else op[1]] += TICK_S
    n = steps - warm
    return [{k: v / n for k, v in a.items()} for a in acc], (t - t_start) / n


def own_segments(rk):
    """CPU seconds per step before each shift, from a rank-interval's timers."""
    t, s = rk["timers"], rk["steps"]
    return (((1 - CONTINUITY_SHARE) * t["comp_s"] + t["integrate_s"]) / s,
            (t["boundary_s"] + t["pack_s"]) / s,
            (t["grid_s"] + t["pairs_s"] + t["idsort_s"] + CONTINUITY_SHARE * t["comp_s"]) / s)


def shares_of(runs):
    tot = [0.0, 0.0, 0.0]
    for d in runs:
        for iv in d["intervals"]:
            for rk in iv["ranks"]:
                if rk["field_mean"] > 0 and rk["steps"] >= 1:
                    for k, v in enumerate(own_segments(rk)):
                        tot[k] += v * rk["steps"]
    if sum(tot) <= 0:
        fail("--shares-from: no busy rank in those runs")
    return [v / sum(tot) for v in tot]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("report", help="sph report of a time-shared run")
    ap.add_argument("--prediction", help="sphmodel prediction: replay its compute instead")
    ap.add_argument("--shares-from", nargs="+", default=[],
                    help="sph reports within the cores: how compute splits between segments")
    ap.add_argument("--slice-ms", type=float, default=1.5,
                    help="scheduler slice of a computing rank (ms)")
    ap.add_argument("--cores", type=int, default=os.cpu_count(), help="cores ranks share")
    ap.add_argument("--steps", type=int, default=20, help="steps replayed per interval")
    a = ap.parse_args()
    if not a.slice_ms > 0:
        fail(f"--slice-ms {a.slice_ms}: expected a number > 0")
    if a.cores < 1 or a.steps < 3:
        fail(f"--cores {a.cores} / --steps {a.steps}: expected >= 1 core and >= 3 steps")
    if a.prediction and not a.shares_from:
        fail("--prediction needs --shares-from (calibration runs within the cores)")
    d = load(a.report, "sph")
    ranks = d["config"]["ranks"]
    predicted = None
    if a.prediction:
        p = load(a.prediction, "sphmodel-prediction")
        kind = d.get("decomposition", {}).get("kind", "equal")
        match = [c for c in p["configurations"] if c["ranks"] == ranks and
                 c["threads"] == d["config"]["threads"] and
                 c.get("decomposition", "equal") == kind]
        if not match:
            fail(f"{a.prediction}: no configuration of {ranks} ranks like {a.report}")
        predicted = match[0]["intervals"]
        if len(predicted) != len(d["intervals"]):
            fail(f"{a.prediction}: {len(predicted)} intervals, the report {len(d['intervals'])}")
        share = shares_of([load(f, "sph") for f in a.shares_from])
    errors, sums = [], dict.fromkeys(("wait_sim", "wait", "comm_sim", "comm"), 0.0)
    print(f"{a.report}: {ranks} ranks on {a.cores} cores, slice {a.slice_ms} ms; per step, summed "
          f"over ranks, simulated / measured (ms)")
    for k, iv in enumerate(d["intervals"]):
        steps = iv["ranks"][0]["steps"]
        if predicted:
            seg = [tuple(rk["compute_s"] / steps * s for s in share) for rk in predicted[k]["ranks"]]
        else:
            seg = [own_segments(rk) for rk in iv["ranks"]]
        res, step_s = simulate(seg, a.cores, a.slice_ms * 1e-3, a.steps)
        wait_sim, comm_sim = sum(x["wait"] for x in res), sum(x["comm"] for x in res)
        wait = sum(rk["timers"]["wait_s"] for rk in iv["ranks"]) / steps
        comm = sum(rk["timers"]["comm_s"] for rk in iv["ranks"]) / steps
        if comm > 0:
            errors.append(comm_sim / comm - 1)
        for key, v in zip(sums, (wait_sim, wait, comm_sim, comm)):
            sums[key] += v * steps
        print(f"  step {iv['step']:6d}: step {1e3 * step_s:7.2f}  wait {1e3 * wait_sim:6.2f} / "
              f"{1e3 * wait:6.2f}  comm {1e3 * comm_sim:6.2f} / {1e3 * comm:6.2f}")
    print(f"run: wait {sums['wait_sim']:.2f} / {sums['wait']:.2f} s, comm {sums['comm_sim']:.2f} / "
          f"{sums['comm']:.2f} s; per-interval |comm error| median "
          f"{100 * statistics.median(abs(e) for e in errors):.1f} %")


if __name__ == "__main__":
    main()
