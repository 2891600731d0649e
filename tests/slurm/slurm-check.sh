#!/usr/bin/env bash
# Tests that run under a real Slurm when one is up (SLURM_CONF set and sinfo answers; CI starts
# one with scripts/slurm/local-slurm.sh):
#   slurm-check.sh main-job BUILD RESULTS  the main job at smoke sizes: through
#       `sbatch --wait scripts/slurm/characterise-node.sbatch --quick` under Slurm, directly
#       otherwise; then its JSON outputs are read back.
#   slurm-check.sh threads BUILD           a 2-rank sph through `srun --mpi=pmix` must give each
#       rank 1 thread on its own core of this 2-core node, and STREAM in a 1-CPU task must
#       measure 1 thread inside its CPU (exit 77, skipped, without Slurm).
#   slurm-check.sh nodes BUILD RESULTS     starts its own Slurm of 2 emulated nodes
#       (local-slurm.sh --nodes 2, ports 6837-6839), submits pingpong-nodes.sbatch --quick with
#       sbatch --wait, checks the other_node class reached machine.json, runs a 2-node sph
#       through srun and validates a --nodes 2 prediction of it (exit 77 without root, Slurm or
#       2 CPUs).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
mode=${1:?mode: main-job, threads or nodes}
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
# The short runs ran 3 times: one of each validated (not three), and their first runs apart.
import glob, os
d = os.path.dirname(sys.argv[1])
reps = glob.glob(os.path.join(d, "repeats", "*.rep*.json"))
names = {os.path.basename(p).split(".rep")[0] for p in reps}
assert len(names) >= 4, f"repeats/ holds runs of {len(names)} configurations, expected the short set"
assert len(reps) == 3 * len(names), f"repeats/ holds {len(reps)} runs of {len(names)} configurations, expected 3 each"
for name in names:
    assert os.path.exists(os.path.join(d, "runs", name + ".json")), f"runs/ lacks the median run of {name}"
print(f"slurm-check: repeats/ holds 3 runs each of {len(names)} short configurations")
# A --quick job's figures mean nothing: it keeps no job for the bias over jobs (keep-job.py).
assert not os.path.exists(os.path.join(d, "jobs")), "a --quick job kept its validation in jobs/"
first = json.load(open(os.path.join(d, "first-runs", "validation.json")))
assert first["summary"]["wall_abs_error"]["count"] == n, "first-runs/ validates another set"
md = open(os.path.join(d, "validation.md")).read()
assert "run 3 times each" in md, "validation.md: no repeats"
# The summary comes first and carries this validation's own headline figures.
head = md.split("## Detail")[0]
assert "## Summary" in head, "validation.md: no summary before the detail"
assert "`--quick` job" in head, "validation.md: a --quick job's summary does not say so"
w = v["summary"]["wall_abs_error"]
for key in ("median", "max"):
    assert f"{100 * w[key]:.1f} %" in head, f"validation.md: the summary lacks the wall {key} error"
PY
    echo "profile: $results/$host/machine.json"
    echo "slurm-check: main job OK" # ctest passes on this line only: every check above ran
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
    env -u SLURM_CPUS_PER_TASK srun -N 1 -n 1 -c 1 "$build/bin/stream" --quiet --size 200000 \
        --reps 2 --affinity compact --vector-bits 128 --json "$scratch/s.json" ||
        fail "srun stream failed"
    python3 - "$scratch/s.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
a, res = s["allocation"], s["results"]
print(f"slurm-check: stream in a 1-CPU task: bound to PU {a['bound_pus']}, "
      f"threads {[r['threads'] for r in res]}, on {[r['placement'][0]['cpuset'] for r in res]}")
assert [r["threads"] for r in res] == [1], "stream swept more threads than its one CPU"
assert all(r["placement"][0]["cpuset"] == a["bound_pus"] for r in res), "stream left its CPU"
PY
    echo "slurm-check: threads OK"
    ;;
nodes)
    [ "$(id -u)" -eq 0 ] && command -v slurmctld >/dev/null && [ "$(nproc)" -ge 2 ] ||
        { echo "slurm-check: needs root, Slurm (install-deps.sh --with-slurm) and 2 CPUs: skipped"; exit 77; }
    results=${3:?results directory}
    rm -rf "$results"
    host=$(hostname)
    mkdir -p "$results/$host"
    slurm_dir=$(mktemp -d)
    export SPHPERF_SLURMCTLD_PORT=${SPHPERF_NODES_CTLD_PORT:-6837}
    export SPHPERF_SLURMD_PORT=$((SPHPERF_SLURMCTLD_PORT + 1))
    trap 'bash "$root/scripts/slurm/local-slurm.sh" stop --dir "$slurm_dir" >/dev/null || true; rm -rf "$slurm_dir"' EXIT
    bash "$root/scripts/slurm/local-slurm.sh" start --dir "$slurm_dir" --nodes 2
    export SLURM_CONF=$slurm_dir/slurm.conf
    # The main job's reports of this node, as the shipped reference left them.
    ref="$root/results/reference/vm"
    cp "$ref"/{stream,dgemm,pingpong,machine}.json "$ref"/exchange_r*.json "$results/$host/"
    SPHPERF_ROOT=$root SPHPERF_BUILD_DIR=$build SPHPERF_RESULTS_DIR=$results \
        sbatch --wait -N 2 --output="$results/slurm-%j.out" \
        "$root/scripts/slurm/pingpong-nodes.sbatch" --quick ||
        { cat "$results"/slurm-*.out >&2 || true; fail "the batch job failed"; }
    grep -v '^ *[0-9]' "$results"/slurm-*.out
    # A short 2-node run (no --threads: 1 per rank from the allocation) to validate against.
    env -u OMP_NUM_THREADS srun --mpi=pmix -N 2 -n 2 "$build/bin/sph" --quiet --setup dambreak \
        --scale 0.5 --steps 100 --interval 50 --report "$results/sph_2nodes.json" ||
        fail "srun sph on 2 nodes failed"
    "$build/bin/sphmodel" calibrate --allow-other-host --machine "$results/$host/machine.json" \
        --runs "$ref"/runs/cal_*.json --out "$results/model.json" >/dev/null ||
        fail "calibrate with the merged profile failed"
    "$build/bin/sphmodel" predict --model "$results/model.json" --setup dambreak --grid table \
        --scale 0.5 --ranks 2 --steps 100 --interval 50 --nodes 2 \
        --out "$results/prediction_2nodes.json" >/dev/null || fail "predict --nodes 2 failed"
    "$build/bin/sphmodel" validate --prediction "$results/prediction_2nodes.json" \
        --measured "$results/sph_2nodes.json" --out "$results/validation_2nodes.json" ||
        fail "validate failed"
    python3 - "$results" "$host" <<'PY'
import json, sys
d, host = sys.argv[1], sys.argv[2]
pp = json.load(open(f"{d}/{host}/pingpong-nodes.json"))
nodes = {r["node"] for r in pp["rank_placement"]}
assert len(nodes) == 2, f"ping-pong ranks on {nodes}, expected 2 nodes"
assert [p["locality"] for p in pp["pairs"]] == ["other_node"], pp["pairs"]
m = json.load(open(f"{d}/{host}/machine.json"))
assert "other_node" in m["hockney"]["classes"], "machine.json lacks the other_node class"
assert "same_l3" in m["hockney"]["classes"] or len(m["hockney"]["classes"]) > 1, \
    "the node's own classes were lost in the merge"
run = json.load(open(f"{d}/sph_2nodes.json"))
assert run["nodes"] == 2 and run["config"]["threads"] == 1, (run["nodes"], run["config"]["threads"])
v = json.load(open(f"{d}/validation_2nodes.json"))
rows = v["configurations"]
assert len(rows) == 1 and rows[0]["nodes"] == 2, "the 2-node run was not matched to --nodes 2"
c = rows[0]["phases"]["comm"]
print(f"slurm-check: other_node alpha {m['hockney']['classes']['other_node']['pieces'][0]['alpha_s']*1e6:.2f} us; "
      f"2-node sph wall {rows[0]['measured_wall_s']:.3f} s predicted {rows[0]['predicted_wall_s']:.3f} s, "
      f"comm {c['measured_s']*1e3:.1f} ms predicted {c['predicted_s']*1e3:.1f} ms")
PY
    echo "slurm-check: nodes OK"
    ;;
*) echo "slurm-check: unknown mode '$mode' (expected main-job, threads or nodes)" >&2; exit 2 ;;
esac
