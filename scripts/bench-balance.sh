#!/usr/bin/env bash
# Balanced against equal slabs on this node: the dam break at scale 1 on 1 rank, and on 2 ranks
# with equal and with balanced slabs, REPEATS times each in turn (1 thread per rank); then the
# calibrated model predicts the same three configurations blind, and validates itself on them.
#   scripts/bench-balance.sh --model MODEL.json --out DIR [--repeats N] [--steps N] [--grid G]
# Defaults: 3 repeats, 1500 steps (0.15 s, the reach of the shipped model's memory-order
# record), grid table. Writes DIR/runs/*.json, DIR/prediction.json, DIR/validation.json and
# DIR/summary.json (medians, speed-ups, idle fractions). Nothing else should run meanwhile.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build="${SPHPERF_BUILD_DIR:-$root/build}"
usage() { sed -n '2,8p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }
model="" out="" repeats=3 steps=1500 grid=table
positive() { [[ "$2" =~ ^[1-9][0-9]*$ ]] || { echo "bench-balance.sh: $1 must be a positive integer, got '$2'" >&2; exit 2; }; }
while [ $# -gt 0 ]; do
    case "$1" in
        --model) [ $# -ge 2 ] || usage 2; model="$2"; shift 2 ;;
        --out) [ $# -ge 2 ] || usage 2; out="$2"; shift 2 ;;
        --repeats) [ $# -ge 2 ] || usage 2; positive --repeats "$2"; repeats="$2"; shift 2 ;;
        --steps) [ $# -ge 2 ] || usage 2; positive --steps "$2"; steps="$2"; shift 2 ;;
        --grid) [ $# -ge 2 ] || usage 2; grid="$2"; shift 2 ;;
        -h|--help) usage 0 ;;
        *) echo "bench-balance.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done
[ -n "$model" ] && [ -n "$out" ] || usage 2
[ -f "$model" ] || { echo "bench-balance.sh: model '$model' not found" >&2; exit 2; }
case "$grid" in list|table|sorted) ;; *) echo "bench-balance.sh: --grid '$grid': expected list, table or sorted" >&2; exit 2 ;; esac
interval=250
common=(--quiet --threads 1 --setup dambreak --scale 1 --grid "$grid" --steps "$steps" --interval "$interval")
mkdir -p "$out/runs"
rm -f "$out"/runs/*.json
for k in $(seq 1 "$repeats"); do
    for cfg in "1 equal" "2 equal" "2 balanced"; do
        set -- $cfg
        name="r$1_$2_$k"
        t0=$SECONDS
        bash "$root/scripts/mpirun.sh" -n "$1" -t 1 "$build/bin/sph" "${common[@]}" \
            --decomposition "$2" --report "$out/runs/$name.json" >/dev/null
        printf '  %-20s %4d s\n' "$name" $((SECONDS - t0))
    done
done
"$build/bin/sphmodel" predict --model "$model" --setup dambreak --grid "$grid" --scale 1 \
    --steps "$steps" --interval "$interval" --ranks 1,2 --threads 1 \
    --decomposition equal,balanced --out "$out/prediction.json"
"$build/bin/sphmodel" validate --prediction "$out/prediction.json" --measured "$out"/runs/*.json \
    --out "$out/validation.json" >/dev/null

/usr/bin/python3 - "$out" <<'EOF'
import json, glob, statistics, sys, os
out = sys.argv[1]
runs = {}
for f in sorted(glob.glob(os.path.join(out, "runs", "*.json"))):
    j = json.load(open(f))
    key = (j["config"]["ranks"], j["decomposition"]["kind"])
    idle = max(j["idle_s"]) if isinstance(j.get("idle_s"), list) else j["totals"]["idle_s"]["max"]
    runs.setdefault(key, []).append((j["wall_s"], idle / j["wall_s"]))
val = json.load(open(os.path.join(out, "validation.json")))
pred = {(c["ranks"], c["decomposition"]): c["wall_s"]
        for c in json.load(open(os.path.join(out, "prediction.json")))["configurations"]}
base = statistics.median(w for w, _ in runs[(1, "equal")])
summary = {"schema": 1, "benchmark": "balance-summary", "configurations": []}
for (ranks, dec), v in sorted(runs.items()):
    walls = [w for w, _ in v]
    errs = [r["wall_error"] for r in val["configurations"]
            if r["ranks"] == ranks and r["decomposition"] == dec]
    summary["configurations"].append({
        "ranks": ranks, "decomposition": dec,
        "wall_s_median": statistics.median(walls), "wall_s_min": min(walls), "wall_s_max": max(walls),
        "speedup_median": base / statistics.median(walls),
        "idle_fraction_max": max(i for _, i in v),
        "predicted_wall_s": pred[(ranks, dec)],
        "wall_error_median": statistics.median(errs) if errs else None})
json.dump(summary, open(os.path.join(out, "summary.json"), "w"), indent=2)
print("  %-9s %5s %12s %9s %9s %12s %9s" % ("slabs", "ranks", "wall_s(med)", "speedup", "idle_max", "predicted_s", "error"))
for c in summary["configurations"]:
    print("  %-9s %5d %12.2f %9.2f %8.1f%% %12.2f %8.1f%%" % (
        c["decomposition"], c["ranks"], c["wall_s_median"], c["speedup_median"],
        100 * c["idle_fraction_max"], c["predicted_wall_s"], 100 * (c["wall_error_median"] or 0)))
EOF
