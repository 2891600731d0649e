#!/usr/bin/env bash
# A main job's measured runs calibrated again, some calibration runs left out or shortened: what a
# cheaper calibration would have predicted for the same validation runs, and what it costs.
#   scripts/replay-job.sh (--runs DIR --machine MACHINE.json | --commit REV [--host H])
#       --out DIR [--exclude REGEX] [--include REGEX] [--shorten REGEX=F]... [--quick]
# --runs: a job's runs (DIR/cal_*.json and DIR/val_*.json, as scripts/model-node.sh writes
# them); --commit: the job stored in results/reference/H/ (default vm) at git revision REV.
# --exclude / --include: extended regular expressions on the calibration reports' paths (the
# model's calibration runs are cal_*.json; round a's end in _a.json, b's in _b.json, Cell+Sorted's
# round c in _c.json). --shorten REGEX=F (repeatable; the first matching rule wins): the kept
# calibration reports whose path matches REGEX cut to their first F (0 < F <= 1) of intervals,
# what a shorter calibration run would have reported (scripts/shorten-report.py: the same
# physics, wall_s scaled by the kept share of the run's timers), written to DIR/shortened/.
# --quick: the runs are a --quick job's (its validation lengths).
# Writes DIR/{model,prediction_*,validation}.json (sphmodel's), prints validate's table and the
# calibration's cost: the run time of the calibration runs kept over that of the validation runs
# (the reports' wall_s, without the launcher's start-up). Nothing is timed: runs beside anything.
# Environment: CAL_EXTRA, more calibrate options; PREDICT_EXTRA, more predict options (the
# model reads each slab's memory order from its columns at simulated time since session 91;
# PREDICT_EXTRA="--memory-order-time froude" is session 90's, "--memory-order-time simulated"
# sessions 59-89's; CAL_EXTRA="--order-line-gauge run" fits the order's cost line as sessions
# 56-90 did, "--order-line-gauge interval" as sessions 91-92 did); REPLAY_RULE, the compute-cost term rule (calibrate --term-selection; default
# the main job's, levelled-best).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build="${SPHPERF_BUILD_DIR:-$root/build}"
stage() { echo "== $*"; }
usage() { sed -n '2,23p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }
die() { echo "replay-job.sh: $*" >&2; exit 2; }
runs="" machine="" commit="" host=vm out="" exclude="" include="" quick=0
shorten=()
while [ $# -gt 0 ]; do
    case "$1" in
        --runs | --machine | --commit | --host | --out | --exclude | --include)
            [ $# -ge 2 ] || die "$1 needs a value (see --help)"
            v=$2
            case "$1" in
                --runs) runs=$v ;; --machine) machine=$v ;; --commit) commit=$v ;;
                --host) host=$v ;; --out) out=$v ;; --exclude) exclude=$v ;; --include) include=$v ;;
            esac
            shift 2 ;;
        --shorten)
            [ $# -ge 2 ] || die "--shorten needs REGEX=FRACTION (see --help)"
            [[ "$2" == *=* ]] || die "--shorten '$2': expected REGEX=FRACTION, e.g. '_b\\.json\$=0.5'"
            shorten+=("$2")
            shift 2 ;;
        --quick) quick=1; shift ;;
        -h | --help) usage 0 ;;
        *) die "unknown argument '$1' (see --help)" ;;
    esac
done
[ -n "$out" ] || die "--out DIR is required"
if [ -n "$commit" ]; then
    [ -z "$runs" ] && [ -z "$machine" ] || die "--commit replaces --runs and --machine"
    git -C "$root" rev-parse --verify --quiet "$commit^{commit}" >/dev/null ||
        die "--commit '$commit': not a revision of $root"
    job="$out/job"
    rm -rf "$job"
    mkdir -p "$job"
    git -C "$root" archive "$commit" "results/reference/$host/runs" \
        "results/reference/$host/machine.json" 2>/dev/null |
        tar -x -C "$job" --strip-components=3 ||
        die "--commit '$commit': no results/reference/$host/{runs,machine.json} there"
    runs="$job/runs" machine="$job/machine.json"
fi
[ -n "$runs" ] && [ -n "$machine" ] || die "give --runs DIR and --machine FILE, or --commit REV"
[ -f "$machine" ] || die "--machine '$machine': no such file"
for rule in "${shorten[@]}"; do
    f=${rule##*=}
    /usr/bin/python3 -c 'import sys; f = float(sys.argv[1]); sys.exit(0 if 0 < f <= 1 else 1)' \
        "$f" 2>/dev/null || die "--shorten '$rule': fraction '$f' is not a number in 0 < F <= 1"
done
for re in "$exclude" "$include" "${shorten[@]%=*}"; do
    [ -n "$re" ] || continue
    rc=0
    grep -E -q -- "$re" <<<"" 2>/dev/null || rc=$?
    [ "$rc" -le 1 ] || die "'$re': not an extended regular expression"
done
# The dam breaks' lengths as the job ran them: scale 1's (1500 steps until session 59, 1000
# since) and scale 2's (500 until session 89, 1000 since).
run_steps() { # run_steps REPORT: its config.steps
    /usr/bin/python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["config"]["steps"])' "$1" ||
        die "'$1': no config.steps"
}
if [ "$quick" -eq 0 ]; then
    probe="$runs/val_dambreak_s1_table_r1.json"
    [ -f "$probe" ] && REPLAY_V_STEPS=$(run_steps "$probe")
    probe="$runs/val_dambreak_s2_table_r2.json"
    [ -f "$probe" ] && REPLAY_V2_STEPS=$(run_steps "$probe")
fi
source "$root/scripts/model-set.sh"
shopt -s nullglob
mapfile -t cal_reports < <(model_runs 2>/dev/null |
    { [ -n "$include" ] && grep -E -- "$include" || cat; } |
    { [ -n "$exclude" ] && grep -v -E -- "$exclude" || cat; })
val_reports=("$runs"/val_*.json)
[ "${#val_reports[@]}" -gt 0 ] || die "--runs '$runs': no validation reports (val_*.json)"
if [ "${#shorten[@]}" -gt 0 ]; then
    short_dir="$out/shortened"
    rm -rf "$short_dir"
    mkdir -p "$short_dir"
    for i in "${!cal_reports[@]}"; do
        for rule in "${shorten[@]}"; do
            if grep -E -q -- "${rule%=*}" <<<"${cal_reports[$i]}"; then
                dest="$short_dir/$(basename "${cal_reports[$i]}")"
                /usr/bin/python3 "$root/scripts/shorten-report.py" --fraction "${rule##*=}" \
                    "${cal_reports[$i]}" "$dest" || exit 2
                cal_reports[$i]=$dest
                break
            fi
        done
    done
fi
[ "${#cal_reports[@]}" -gt 0 ] || die "no calibration report (cal_*.json in '$runs') is left" \
    "after --include '$include' and --exclude '$exclude'"
# PREDICT_EXTRA: more predict options (e.g. --memory-order-time froude for a job whose list
# and table records end before the validation's simulated time, sessions 55-58).
model_and_validate "$out" "${REPLAY_RULE:-levelled-best}" froude relative replay "${PREDICT_EXTRA:-}"
in_sample "$out"
/usr/bin/python3 - "$out/validation.json" "${#cal_reports[@]}" "${cal_reports[@]}" \
    -- "${val_reports[@]}" <<'PY'
import json, sys
args = sys.argv[3:]
sep = args.index("--")
wall = lambda p: json.load(open(p))["wall_s"]
cal, val = sum(map(wall, args[:sep])), sum(map(wall, args[sep + 1:]))
s = json.load(open(sys.argv[1]))["summary"]["wall_abs_error"]
print(f"calibration: {sys.argv[2]} runs, {cal:.1f} s of run time, {100 * cal / val:.1f} % of the "
      f"validation runs' {val:.1f} s; wall |error| median {100 * s['median']:.1f} %, "
      f"max {100 * s['max']:.1f} %")
PY
