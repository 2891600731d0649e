#!/usr/bin/env python3
"""Measure sphperf's benchmarks beside the reference tools, interleaved in one session.

    python3 scripts/compare-reference.py [--rounds 5] [--out results/<host>/reference_comparison.json]

Memory: our STREAM triad (regular and non-temporal stores) against likwid-bench's stream and
stream_mem kernels on the same array sizes and thread counts. Compute: our FMA peak probe against
likwid-bench peakflops. MPI: our ping-pong one-way times against NetPIPE's at every common size.

The node's bandwidth drifts by tens of percent over minutes (shared host), so tools are run
alternately, round after round, and each ratio is the median of per-round ratios with its
min..max spread. Nothing else may run meanwhile. Installs likwid and NetPIPE if missing.
"""
import argparse
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(os.environ.get("SPHPERF_BUILD_DIR", os.path.join(ROOT, "build")), "bin")
ELEMENT_BYTES = 8
ARRAYS = 3


def sh(cmd, env=None):
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        sys.exit(f"compare-reference: {' '.join(cmd)} failed ({r.returncode}): {r.stderr.strip()}")
    return r.stdout


def cpu_flags():
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    return set()


def likwid_variants():
    """likwid-bench kernels this CPU can run: (triad kernels, non-temporal triad kernels, peak).
    Every triad variant is run and the fastest kept: on Zen 4 its 256-bit kernels beat its
    512-bit ones by ~20% at one thread, so a fixed choice would flatter us."""
    flags = cpu_flags()
    triad, nt = ["stream_sse"], ["stream_mem_sse"]
    if "avx" in flags:
        triad.append("stream_avx")
        nt.append("stream_mem_avx")
    if "avx" in flags and "fma" in flags:
        triad.append("stream_avx_fma")
        nt.append("stream_mem_avx_fma")
    if "avx512f" in flags:
        triad += ["stream_avx512", "stream_avx512_fma"]
        nt.append("stream_mem_avx512")
    peak = "peakflops_avx512_fma" if "avx512f" in flags else (
        "peakflops_avx_fma" if "fma" in flags else "peakflops")
    return triad, nt, peak


def likwid(test, workgroup, unit, iterations=None):
    """likwid-bench's rate in `unit` (MByte/s or MFlops/s), returned in GB/s or GFLOP/s."""
    cmd = ["likwid-bench", "-t", test, "-w", workgroup]
    if iterations:
        cmd += ["-i", str(iterations)]
    out = sh(cmd)
    m = re.search(r"^" + re.escape(unit) + r":\s+([0-9.]+)", out, re.M)
    if not m:
        sys.exit(f"compare-reference: no {unit} in likwid-bench output for {test}")
    return float(m.group(1)) / 1000.0


def ours_stream(n, threads, tmp):
    path = os.path.join(tmp, "stream.json")
    sh([os.path.join(BIN, "stream"), "--size", str(n), "--threads", str(threads), "--affinity",
        "compact", "--quiet", "--json", path])
    # Best over the vector widths our STREAM sweeps, as likwid is taken at its best kernel.
    results = json.load(open(path))["results"]
    best = max(results, key=lambda r: r["kernels"]["triad"]["best_GBps"])
    best_nt = max(results, key=lambda r: r["triad_nt"]["best_GBps"])
    return best["kernels"]["triad"], best_nt["triad_nt"]


def ours_probe(tmp):
    path = os.path.join(tmp, "dgemm.json")
    sh([os.path.join(BIN, "dgemm"), "--sizes", "64", "--reps", "1", "--probe-reps", "3",
        "--quiet", "--json", path])
    return json.load(open(path))["peak_probe"]


def mpirun(ranks):
    return ["bash", os.path.join(ROOT, "scripts", "mpirun.sh"), "-n", str(ranks)]


def ours_pingpong(max_bytes, tmp):
    path = os.path.join(tmp, "pingpong.json")
    sh(mpirun(2) + [os.path.join(BIN, "pingpong"), "--max-bytes", str(max_bytes), "--quiet",
                    "--json", path])
    pair = json.load(open(path))["pairs"][0]
    return {int(s["bytes"]): s["median_s"] for s in pair["samples"]}, pair


def netpipe(max_bytes, tmp):
    out = os.path.join(tmp, "np.out")
    sh(mpirun(2) + ["NPopenmpi", "-p", "0", "-u", str(max_bytes), "-o", out])
    times = {}
    for line in open(out):
        b, _mbps, t = line.split()
        times[int(b)] = float(t)  # NetPIPE's time is one-way (round trip / 2)
    return times


def likwid_best(tests, workgroup, iterations, winners):
    """The fastest of several likwid-bench kernels; counts which one won in `winners`."""
    rates = {t: likwid(t, workgroup, "MByte/s", iterations) for t in tests}
    best = max(rates, key=rates.get)
    winners[best] = winners.get(best, 0) + 1
    return rates[best]


def spread(values):
    return {"median": statistics.median(values), "min": min(values), "max": max(values),
            "n": len(values)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds (default 5)")
    ap.add_argument("--elements", type=int, default=17_000_000,
                    help="elements per array (default 17e6: > 4x a 32 MiB L3, and a whole "
                         "number of likwid kB)")
    ap.add_argument("--max-bytes", type=int, default=4 << 20, help="largest MPI message")
    ap.add_argument("--out", help="JSON output (default results/<host>/reference_comparison.json)")
    args = ap.parse_args()
    if args.rounds < 1:
        sys.exit(f"compare-reference: --rounds {args.rounds} must be >= 1")
    if args.elements <= 0 or (args.elements * ARRAYS * ELEMENT_BYTES) % 1000:
        sys.exit(f"compare-reference: --elements {args.elements} must be positive and give a "
                 "whole number of kB over 3 arrays")
    out = args.out or os.path.join(ROOT, "results", socket.gethostname(),
                                   "reference_comparison.json")

    subprocess.run(["bash", os.path.join(ROOT, "scripts", "install-deps.sh"),
                    "--with-reference-tools"], check=True, stdout=subprocess.DEVNULL)
    for exe in ("stream", "dgemm", "pingpong"):
        if not os.access(os.path.join(BIN, exe), os.X_OK):
            sys.exit(f"compare-reference: {BIN}/{exe} missing; run scripts/build.sh first")

    cores = os.cpu_count() or 1
    thread_counts = sorted({1, cores})
    triad, triad_nt, peak = likwid_variants()
    kb = args.elements * ARRAYS * ELEMENT_BYTES // 1000
    memory = {t: {"ours_best": [], "ours_avg": [], "likwid": [], "ours_nt_best": [],
                  "likwid_nt": []} for t in thread_counts}
    flops = {"ours_per_core": [], "likwid_per_core": [], "ours_all": [], "likwid_all": []}
    mpi_ratio = {}
    winners = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            print(f"round {r + 1}/{args.rounds}", file=sys.stderr)
            for t in thread_counts:
                k, nt = ours_stream(args.elements, t, tmp)
                memory[t]["ours_best"].append(k["best_GBps"])
                memory[t]["ours_avg"].append(k["avg_GBps"])
                memory[t]["ours_nt_best"].append(nt["best_GBps"])
                wg = f"N:{kb}kB:{t}"
                memory[t]["likwid"].append(likwid_best(triad, wg, 20 * t, winners))
                memory[t]["likwid_nt"].append(likwid_best(triad_nt, wg, 20 * t, winners))
            p = ours_probe(tmp)
            flops["ours_per_core"].append(p["per_core_gflops"])
            flops["ours_all"].append(p["all_cores_gflops"])
            flops["likwid_per_core"].append(likwid(peak, "N:32kB:1", "MFlops/s"))
            flops["likwid_all"].append(likwid(peak, f"N:{32 * cores}kB:{cores}", "MFlops/s"))
            ours, pair = ours_pingpong(args.max_bytes, tmp)
            ref = netpipe(args.max_bytes, tmp)
            for b in sorted(set(ours) & set(ref)):
                mpi_ratio.setdefault(b, {"ours_s": [], "netpipe_s": [], "ratio": []})
                mpi_ratio[b]["ours_s"].append(ours[b])
                mpi_ratio[b]["netpipe_s"].append(ref[b])
                mpi_ratio[b]["ratio"].append(ours[b] / ref[b])

    report = {"schema": 1, "benchmark": "reference_comparison", "host": socket.gethostname(),
              "git_commit": sh(["git", "-C", ROOT, "rev-parse", "HEAD"]).strip(),
              "rounds": args.rounds, "elements_per_array": args.elements,
              "likwid_tests": {"triad": triad, "triad_nt": triad_nt, "peak": peak},
              "reference_for_mpi": "NetPIPE (NPopenmpi -p 0), one-way time",
              "memory": [], "compute": {}, "mpi": []}
    print(f"\n{'figure':34s} {'ours':>9s} {'reference':>10s} {'ratio':>7s}  ratio min..max")

    def row(name, ours, ref):
        ratios = [o / r for o, r in zip(ours, ref)]
        s = spread(ratios)
        print(f"{name:34s} {statistics.median(ours):9.2f} {statistics.median(ref):10.2f} "
              f"{s['median']:7.3f}  {s['min']:.3f}..{s['max']:.3f}")
        return {"ours": spread(ours), "reference": spread(ref), "ratio": s}

    for t in thread_counts:
        m = memory[t]
        report["memory"].append({
            "threads": t,
            "triad_best_vs_likwid_GBps": row(f"triad best GB/s, {t} thr vs likwid", m["ours_best"], m["likwid"]),
            "triad_avg_vs_likwid_GBps": row(f"triad avg GB/s, {t} thr vs likwid", m["ours_avg"], m["likwid"]),
            "triad_nt_best_vs_likwid_GBps": row(f"triad NT GB/s, {t} thr vs likwid", m["ours_nt_best"], m["likwid_nt"]),
        })
    report["compute"] = {
        "per_core_gflops": row("FMA peak GFLOP/s, 1 core", flops["ours_per_core"], flops["likwid_per_core"]),
        "all_cores_gflops": row(f"FMA peak GFLOP/s, {cores} cores", flops["ours_all"], flops["likwid_all"]),
    }
    for b in sorted(mpi_ratio):
        v = mpi_ratio[b]
        entry = {"bytes": b, "ours_one_way_s": spread(v["ours_s"]),
                 "netpipe_one_way_s": spread(v["netpipe_s"]), "ratio": spread(v["ratio"])}
        report["mpi"].append(entry)
        if b in (1, 1024, 65536, 1 << 20, args.max_bytes):
            print(f"{'one-way us, ' + str(b) + ' B vs NetPIPE':34s} "
                  f"{statistics.median(v['ours_s']) * 1e6:9.3f} "
                  f"{statistics.median(v['netpipe_s']) * 1e6:10.3f} "
                  f"{entry['ratio']['median']:7.3f}  {entry['ratio']['min']:.3f}..{entry['ratio']['max']:.3f}")
    ratios = [e["ratio"]["median"] for e in report["mpi"]]
    report["mpi_ratio_median_over_sizes"] = statistics.median(ratios)
    print(f"{'MPI one-way ratio, median of sizes':34s} {'':9s} {'':10s} {statistics.median(ratios):7.3f}")
    report["likwid_fastest_kernel_counts"] = winners
    print(f"fastest likwid kernels (times chosen): {winners}")
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    tmp_out = out + ".tmp"
    with open(tmp_out, "w") as f:
        json.dump(report, f, indent=2)
    os.replace(tmp_out, out)
    print(f"written {out}")


if __name__ == "__main__":
    main()
