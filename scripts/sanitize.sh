#!/usr/bin/env bash
# AddressSanitizer + UndefinedBehaviorSanitizer stage: builds the SPH proxy, sphmodel and the
# pure unit tests with -DSPHPERF_SANITIZE=address,undefined (any report aborts: exit non-zero),
# runs the unit tests, then short SPH runs at 1, 2 and 3 ranks on every grid (equal and
# balanced slabs, a checkpoint and a 3 -> 2 rank restart) and a model predict.
#   scripts/sanitize.sh [BUILD_DIR]      (default build-asan)
# About 4 minutes on this 2-core node, 3.4 of them the build; a CI stage (.ci/run).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
case "${1:-}" in -h|--help) sed -n '2,7p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;; esac
build="${1:-$root/build-asan}"
# -O1 with line tables only (-g1): what the sanitizers' own docs advise for speed, and a third
# of the build time of -O2 -g (3.4 against 11 minutes on this node); reports keep file:line.
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DSPHPERF_NATIVE=OFF \
    -DSPHPERF_SANITIZE=address,undefined >/dev/null
cmake --build "$build" -j"$(nproc)" --target sph sphmodel sph_unit_tests model_unit_tests \
    unit_tests >/dev/null
# Open MPI's own allocations at exit would be reported as leaks.
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1
for t in unit_tests sph_unit_tests model_unit_tests; do
    "$build/bin/$t" --gtest_brief=1 >"$build/$t.log" 2>&1 ||
        { echo "sanitize.sh: $t failed (see $build/$t.log)" >&2; exit 1; }
    echo "  $t: $(grep -o 'PASSED  \] [0-9]* tests' "$build/$t.log" | grep -o '[0-9]*') passed"
done
scratch="$build/sanitize-runs"
rm -rf "$scratch" && mkdir -p "$scratch"
sph() { # sph RANKS NAME ARGS...
    local ranks=$1 name=$2
    shift 2
    if ! bash "$root/scripts/mpirun.sh" -n "$ranks" "$build/bin/sph" --quiet --scale 0.25 \
        --interval 50 --report "$scratch/$name.json" "$@" >"$scratch/$name.log" 2>&1; then
        echo "sanitize.sh: sph $name failed:" >&2
        tail -n 20 "$scratch/$name.log" >&2
        exit 1
    fi
    echo "  sph $name: clean"
}
for grid in list table sorted; do
    for r in 1 2 3; do
        sph "$r" "${grid}_r$r" --grid "$grid" --steps 150
    done
    sph 3 "${grid}_balanced_r3" --grid "$grid" --steps 150 --decomposition balanced \
        --rebalance-every 50
done
sph 2 mirror_r2 --boundary mirror --steps 150
# Non-blocking exchanges: their buffers must outlive the transfers (sends complete a step later).
for r in 2 3; do
    sph "$r" "sorted_overlap_r$r" --grid sorted --overlap --steps 150
done
sph 3 sorted_overlap_mirror_balanced_r3 --grid sorted --overlap --boundary mirror --steps 150 \
    --decomposition balanced --rebalance-every 50
# The shared-memory window: ghosts packed into this rank's segment, landed from the neighbours'.
sph 3 sorted_window_overlap_mirror_r3 --grid sorted --overlap --halo-transport window \
    --boundary mirror --steps 150 --decomposition balanced --rebalance-every 50
sph 2 table_window_r2 --grid table --halo-transport window --steps 150
# Particles permuted in place every step (scratch buffers swapped with the arrays).
sph 3 sorted_reorder_mirror_r3 --grid sorted --reorder-every 1 --boundary mirror --steps 150
sph 3 checkpoint_r3 --steps 100 --checkpoint "$scratch/ck" --decomposition balanced
sph 2 restart_r2 --steps 200 --restart "$scratch/ck" --decomposition balanced
"$build/bin/sphmodel" predict --model "$root/results/reference/vm/model.json" --setup dambreak \
    --grid sorted --scale 0.5 --ranks 1,2,4 --steps 500 --decomposition equal,balanced \
    --out "$scratch/prediction.json" >/dev/null
echo "  sphmodel predict: clean"
echo "sanitize.sh: no AddressSanitizer or UBSan report"
