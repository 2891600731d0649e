#!/usr/bin/env bash
# The main job: characterise this node, calibrate the SPH runtime model with short small runs,
# predict a validation set, measure it, validate, and plot (results/<hostname>/).
#   scripts/characterise-node.sh [--compare-coretypes SkylakeX,Haswell] [--quick] [--no-build]
#                                [--no-model]
# Builds if needed, then runs STREAM, DGEMM + peak probe (and DGEMM again with the OpenBLAS core
# type it recommends, if any), ping-pong on one rank per core, then the model (--no-model skips
# it). Nothing else should run on the machine meanwhile: the figures are timings. --quick is a
# smoke run whose figures mean little. SPHPERF_RESULTS_DIR overrides results/.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build="${SPHPERF_BUILD_DIR:-$root/build}"
# Each stage's header says how far into the job it starts (the README's time budget).
: "${SPHPERF_JOB_START:=$(date +%s)}"
export SPHPERF_JOB_START
stage() { echo "== $* ($(($(date +%s) - SPHPERF_JOB_START)) s into the job)"; }

usage() {
    sed -n '2,8p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit "${1:-0}"
}
coretypes=""
quick=0
build_first=1
model=1
while [ $# -gt 0 ]; do
    case "$1" in
        --compare-coretypes) [ $# -ge 2 ] || usage 2; coretypes="$2"; shift 2 ;;
        --quick) quick=1; shift ;;
        --no-build) build_first=0; shift ;;
        --no-model) model=0; shift ;;
        -h|--help) usage 0 ;;
        *) echo "characterise-node.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done

if [ "$build_first" -eq 1 ]; then
    stage "building (log: ${TMPDIR:-/tmp}/sphperf-build.log)"
    # The programs the job runs, not the test suite (a third of a fresh build's time).
    bash "$root/scripts/build.sh" stream dgemm pingpong exchange machine-profile sph sphmodel \
        >"${TMPDIR:-/tmp}/sphperf-build.log" 2>&1 || {
        echo "characterise-node.sh: build failed; see ${TMPDIR:-/tmp}/sphperf-build.log" >&2; exit 1; }
fi

host=$(hostname)
out="${SPHPERF_RESULTS_DIR:-$root/results}/$host"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
ranks=$(nproc)
[ "$ranks" -ge 2 ] || ranks=2

# STREAM sizes its arrays at 4x the last-level cache: with a 480 MB L3 (this VM's host) ten
# repetitions of every kernel, width and thread count took 121 s of the job; best and mean of
# those ten agreed within 2.5 %, so five sufficed (stream's default stays STREAM's ten). With
# the 300 MB L3 of the Intel host (session 45) five took 57 s; the job reads only the best
# triad (the roofline's memory ceiling), so three (+1 dropped) here.
stream_args=(--reps 3)
# DGEMM likewise: ten runs of every size took 46 s of the job (session 35, 4000^2 at 1 thread
# 2.3 s a run); best and mean of those ten agreed within 2.2 %, so five suffice here. On an Intel
# host (session 44) OpenBLAS picks its AVX2 'Prescott' kernels, 4000^2 at 1 thread takes about
# 8 s a run and the DGEMM stage took 132 s: past 10 s of timed runs a size stops (at least 2).
# 4000^2 then still took 41 of the stage's 59 s (session 45) for a figure within 1.3 % of
# 2000^2's there (16.4 against 16.6 GFLOP/s at 1 thread) and 3 % above it on the AMD host (54.3
# against 52.5): the job stops at 2000^2 (dgemm's default keeps 4000^2). Three runs a size
# (session 47): the stage took 11.7 s against 17.5 s with five, best 29.7 against 29.4 GFLOP/s.
dgemm_args=(--reps 3 --max-seconds 10 --sizes 1000,2000)
pingpong_args=()
# The halo exchange benchmarks at 0.15 s a point (exchange's default 0.3; at least 20 rounds
# either way, so the 10 and 30 ms gaps keep their length): 41 s of the job on the Intel host
# (session 45). The validation runs within the cores read their own fresh benchmark (0.1 s a
# point since session 45: the mean shift cost's variation over repeats 8.5 against 6.4 % at
# 0.2 s, model/NOTES.md); these serve the runs without one and the loads above the cores.
exchange_args=(--seconds-per-point 0.15)
# Above the cores the model in use replays the step (its shifts included) from the app's own
# calibration runs; these benchmarks serve other loads and the comparison models, at 0.1 s a
# point and 10 rounds (15 s of the job at 3 and 4 ranks in session 47, the 30 ms gap's 20
# rounds alone 1.8 s of each).
exchange_shared_args=(--seconds-per-point 0.1 --min-rounds 10)
if [ "$quick" -eq 1 ]; then # a smoke run: small sizes, seconds not minutes
    stream_args=(--size 2000000 --reps 3)
    dgemm_args=(--sizes 300 --reps 2 --probe-reps 1)
    pingpong_args=(--max-bytes 65536 --max-samples 50)
    exchange_args=(--gaps-us 0,1000,10000 --payload-bytes 64,4096 --seconds-per-point 0.02
        --min-rounds 5)
    exchange_shared_args=("${exchange_args[@]}")
fi

stage "STREAM"
"$build/bin/stream" "${stream_args[@]}" --json "$work/stream.json"
stage "DGEMM"
"$build/bin/dgemm" "${dgemm_args[@]}" --json "$work/dgemm.json"

suggested=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1])).get("suggested_coretype") or "")' "$work/dgemm.json")
for ct in $(echo "$suggested,$coretypes" | tr ',' ' '); do
    [ -f "$work/dgemm_$ct.json" ] && continue
    stage "DGEMM with OPENBLAS_CORETYPE=$ct"
    OPENBLAS_CORETYPE="$ct" "$build/bin/dgemm" "${dgemm_args[@]}" --no-probe --threads "$(nproc)" \
        --json "$work/dgemm_$ct.json"
done

stage "ping-pong on $ranks ranks"
bash "$root/scripts/mpirun.sh" -n "$ranks" "$build/bin/pingpong" "${pingpong_args[@]}" \
    --json "$work/pingpong.json"

# The app's halo exchange at 2 ranks, at the core count and above it (time-sharing), so the
# model knows what a shift costs after compute at every load it predicts.
cores=$(nproc)
for n in $(printf '%s\n' 2 "$cores" $((cores + cores / 2)) $((2 * cores)) | sort -nu); do
    [ "$n" -ge 2 ] || continue
    # Within the cores also a shift right after another (the app's ghosts after its
    # migration) and overlapped (sph --overlap): what posting and completing the same shift
    # leaves exposed behind compute. Above them a rank's turn decides, not the order or overlap.
    modes=()
    [ "$n" -le "$cores" ] && modes=(--following --overlapped)
    stage "halo exchange on $n ranks${modes:+ (blocking, following and overlapped)}"
    args=("${exchange_args[@]}")
    [ "$n" -le "$cores" ] || args=("${exchange_shared_args[@]}")
    bash "$root/scripts/mpirun.sh" -n "$n" "$build/bin/exchange" "${args[@]}" \
        "${modes[@]}" --quiet --json "$work/exchange_r$n.json"
done

mkdir -p "$out"
# This run's reports replace the last ones (an earlier run's extra core type or rank count must
# not join the profile); an inter-node ping-pong of this node (pingpong-nodes.sbatch) stays.
rm -f "$out"/dgemm_*.json "$out"/exchange_r*.json
cp "$work"/*.json "$out/"
bash "$root/scripts/merge-profile.sh" "$out"

if [ "$model" -eq 0 ]; then
    echo "profile: $out/machine.json"
    exit 0
fi
bash "$root/scripts/model-node.sh" $([ "$quick" -eq 1 ] && echo --quick) --machine "$out/machine.json" \
    --out "$out"
echo "profile: $out/machine.json"
stage "main job done"
