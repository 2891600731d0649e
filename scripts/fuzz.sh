#!/usr/bin/env bash
# Builds the libFuzzer harnesses (tests/fuzz: checkpoint files and manifest, benchmark and SPH
# reports, model.json) with clang, AddressSanitizer and UBSan, and runs each for SECONDS.
#   scripts/fuzz.sh SECONDS        (install clang first: scripts/install-deps.sh --with-fuzz)
# Seeds come from results/ (real reports and model) and a tiny checkpoint; findings are written
# to build-fuzz/findings/<harness>/. Exit 1 on the first finding. Not run by CI.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
usage() { sed -n '2,6p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }
[ $# -eq 1 ] || usage 2
case "$1" in -h|--help) usage 0 ;; esac
[[ "$1" =~ ^[1-9][0-9]*$ ]] || { echo "fuzz.sh: SECONDS must be a positive integer, got '$1'" >&2; exit 2; }
seconds=$1
command -v clang++ >/dev/null || { echo "fuzz.sh: clang++ not found: scripts/install-deps.sh --with-fuzz" >&2; exit 2; }
build="${SPHPERF_FUZZ_BUILD_DIR:-$root/build-fuzz}"
CXX=clang++ cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSPHPERF_FUZZ=ON \
    -DSPHPERF_BUILD_TESTS=OFF -DSPHPERF_NATIVE=OFF >/dev/null
cmake --build "$build" -j"$(nproc)" --target fuzz_checkpoint fuzz_reports fuzz_model sph >/dev/null

# Seeds: every kind of input from a real run.
seeds="$build/seeds"
rm -rf "$seeds" && mkdir -p "$seeds"/{checkpoint,reports,model}
ck="$build/seed_checkpoint"
rm -rf "$ck"
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 ASAN_OPTIONS=detect_leaks=0 \
    "$build/bin/sph" --quiet --scale 0.25 --steps 20 --interval 10 --checkpoint "$ck" >/dev/null
cp "$ck"/manifest.json "$seeds/checkpoint/"
for f in "$ck"/step_*/*.bin; do cp "$f" "$seeds/checkpoint/$(basename "$f")"; done
ref=$(ls -d "$root"/results/*/ | head -n 1)
k=0
for kind in stream dgemm dgemm pingpong exchange_r2; do
    f="$ref/$kind.json"
    [ -f "$f" ] || continue
    # The first byte picks the kind (tests/fuzz/fuzz_reports.cpp).
    { printf "\\x$(printf %02x $k)"; cat "$f"; } >"$seeds/reports/${kind}_$k.json"
    k=$((k + 1))
done
for f in "$ref"/runs/cal_still_s0.5_table_a.json; do [ -f "$f" ] && { printf '\x00'; cat "$f"; } >"$seeds/reports/sph.json"; done
[ -f "$ref/model.json" ] && cp "$ref/model.json" "$seeds/model/"

status=0
for h in checkpoint reports model; do
    mkdir -p "$build/findings/$h" "$build/corpus/$h"
    echo "== fuzz_$h: $seconds s"
    if ! ASAN_OPTIONS=detect_leaks=0 "$build/bin/fuzz_$h" -max_total_time="$seconds" \
        -artifact_prefix="$build/findings/$h/" -print_final_stats=1 \
        "$build/corpus/$h" "$seeds/$h" 2>"$build/fuzz_$h.log"; then
        echo "fuzz_$h: FINDING (see $build/fuzz_$h.log and $build/findings/$h/)" >&2
        status=1
    fi
    grep -E "^stat::number_of_executed_units|^stat::new_units_added" "$build/fuzz_$h.log" | sed 's/^/  /'
done
exit $status
