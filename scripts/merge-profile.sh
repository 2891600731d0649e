#!/usr/bin/env bash
# Builds a machine profile from the benchmark reports in DIR (as the main job leaves them):
# stream.json, dgemm.json, dgemm_<coretype>.json, pingpong.json, exchange_r<N>.json and, when
# present, pingpong-nodes.json (the inter-node class, scripts/slurm/pingpong-nodes.sbatch).
#   scripts/merge-profile.sh DIR [OUT]     (OUT default DIR/machine.json)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build="${SPHPERF_BUILD_DIR:-$root/build}"
case "${1:-}" in -h|--help) sed -n '2,5p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    '') echo "merge-profile.sh: expected DIR [OUT] (see --help)" >&2; exit 2 ;; esac
dir=$1
out=${2:-$dir/machine.json}
for f in stream dgemm pingpong; do
    [ -f "$dir/$f.json" ] || { echo "merge-profile.sh: $dir/$f.json is missing (run the main job)" >&2; exit 2; }
done
args=(--stream "$dir/stream.json" --dgemm "$dir/dgemm.json" --pingpong "$dir/pingpong.json")
for f in "$dir"/dgemm_*.json; do [ -f "$f" ] && args+=(--dgemm-alt "$f"); done
exchanges=()
for f in "$dir"/exchange_r*.json; do [ -f "$f" ] && exchanges+=("$f"); done
[ ${#exchanges[@]} -eq 0 ] || args+=(--exchange "${exchanges[@]}")
[ -f "$dir/pingpong-nodes.json" ] && args+=(--pingpong-nodes "$dir/pingpong-nodes.json")
"$build/bin/machine-profile" "${args[@]}" --out "$out"
