#!/usr/bin/env bash
# Tests that run under a real Slurm when one is up (SLURM_CONF set and sinfo answers; CI starts
# one with scripts/slurm/local-slurm.sh):
#   slurm-check.sh main-job BUILD RESULTS  the main job at smoke sizes: through
#       `sbatch --wait scripts/slurm/characterise-node.sbatch --quick` under Slurm, directly
#       otherwise; then its JSON outputs are read back.
#   slurm-check.sh threads BUILD           a 2-rank sph through `srun --mpi=pmix` must give each
#       rank 1 thread on its own core of this 2-core node (exit 77, skipped, without Slurm).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
mode=${1:?mode: main-job or threads}
build=${2:?build directory}
slurm_up() { [ -n "${SLURM_CONF:-}" ] && command -v sbatch >/dev/null && sinfo -h >/dev/null 2>&1; }
fail() { echo "slurm-check: $*" >&2; exit 1; }

case "$mode" in
main-job)
    results=${3:?results directory}
    rm -rf "$results"
    mkdir -p "$results"
    if slurm_up; then
        echo "slurm-check: submitting characterise-node.sbatch --quick (SLURM_CONF=$SLURM_CONF)"
        SPHPERF_ROOT=$root SPHPERF_BUILD_DIR=$build SPHPERF_RESULTS_DIR=$results \
            sbatch --wait --output="$results/slurm-%j.out" \
            "$root/scripts/slurm/characterise-node.sbatch" --quick --no-build ||
            { cat "$results"/slurm-*.out >&2 || true; fail "the batch job failed"; }
        cat "$results"/slurm-*.out
    else
        echo "slurm-check: no Slurm up; the main job runs directly"
        SPHPERF_BUILD_DIR=$build SPHPERF_RESULTS_DIR=$results \
            bash "$root/scripts/characterise-node.sh" --quick --no-build
    fi
    host=$(hostname)
    for f in machine model validation; do
        python3 -c "import json, sys; json.load(open(sys.argv[1]))" "$results/$host/$f.json" ||
            fail "$results/$host/$f.json is missing or not JSON"
    done
    python3 - "$results/$host/validation.json" <<'PY'
import json, sys
v = json.load(open(sys.argv[1]))
n = v["summary"]["wall_abs_error"]["count"]
assert n >= 10, f"validation.json holds {n} configurations, expected the main job's set"
print(f"slurm-check: validation.json holds {n} configurations")
PY
    echo "profile: $results/$host/machine.json"
    ;;
threads)
    slurm_up || { echo "slurm-check: no Slurm up (SLURM_CONF unset or sinfo fails): skipped"; exit 77; }
    scratch=$(mktemp -d)
    trap 'rm -rf "$scratch"' EXIT
    # No --threads and no OMP_NUM_THREADS: sph must take its count from the allocation.
    env -u OMP_NUM_THREADS srun --mpi=pmix -N 1 -n 2 "$build/bin/sph" --quiet --setup dambreak \
        --scale 0.5 --steps 50 --report "$scratch/r.json" 2>"$scratch/err" ||
        { cat "$scratch/err" >&2; fail "srun sph failed"; }
    python3 - "$scratch/r.json" "$(nproc)" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
cores = int(sys.argv[2])
threads, ranks, pus = r["config"]["threads"], r["config"]["ranks"], r["placement_pus"]
print(f"slurm-check: {ranks} ranks x {threads} thread(s), ranks on PUs {pus}, "
      f"{r['steps_per_s']:.0f} steps/s")
assert ranks == 2, f"{ranks} ranks, expected 2"
expected = max(1, cores // 2)
assert threads == expected, f"{threads} threads per rank, expected {expected} on {cores} cores"
assert len(set(pus)) == len(pus), f"ranks share a PU: {pus}"
PY
    grep -q "warning" "$scratch/err" && { cat "$scratch/err" >&2; fail "sph warned"; }
    echo "slurm-check: threads OK"
    ;;
*) echo "slurm-check: unknown mode '$mode' (expected main-job or threads)" >&2; exit 2 ;;
esac
