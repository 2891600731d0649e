#!/usr/bin/env bash
# Soak: a long dam break at 1, 2, 3 and 4 ranks, each checked for lost particles, mass drift,
# escaped fluid and memory growth (resident set flat after the first report interval).
#   scripts/soak.sh [--steps N] [--scale S] [--grid G] [--out DIR]
# Defaults: 100000 steps (10 s of simulated time: the water sloshes to rest), scale 0.25, grid
# table, DIR build/soak. Writes DIR/soak_r<RANKS>.json and DIR/summary.json; exit 1 when a check
# fails. Not run by CI (minutes).
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build="${SPHPERF_BUILD_DIR:-$root/build}"
usage() { sed -n '2,7p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }
steps=100000 scale=0.25 grid=table out="$build/soak"
while [ $# -gt 0 ]; do
    case "$1" in
        --steps) [ $# -ge 2 ] || usage 2; steps="$2"; shift 2 ;;
        --scale) [ $# -ge 2 ] || usage 2; scale="$2"; shift 2 ;;
        --grid) [ $# -ge 2 ] || usage 2; grid="$2"; shift 2 ;;
        --out) [ $# -ge 2 ] || usage 2; out="$2"; shift 2 ;;
        -h|--help) usage 0 ;;
        *) echo "soak.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done
[[ "$steps" =~ ^[1-9][0-9]*$ ]] && [ "$steps" -ge 40 ] ||
    { echo "soak.sh: --steps must be an integer >= 40, got '$steps'" >&2; exit 2; }
interval=$((steps / 20))
mkdir -p "$out"
for ranks in 1 2 3 4; do
    t0=$SECONDS
    # sph itself stops on a lost particle (count and mass checked every interval) or a NaN.
    bash "$root/scripts/mpirun.sh" -n "$ranks" -t 1 "$build/bin/sph" --quiet --threads 1 \
        --setup dambreak --scale "$scale" --grid "$grid" --steps "$steps" --interval "$interval" \
        --report "$out/soak_r$ranks.json" >/dev/null
    printf '  %d rank(s): %d s\n' "$ranks" $((SECONDS - t0))
done

/usr/bin/python3 - "$out" <<'EOF'
import json, os, sys
out = sys.argv[1]
summary = {"schema": 1, "benchmark": "soak-summary", "runs": []}
ok = True
print("  %5s %9s %8s %16s %8s %20s %s" % ("ranks", "steps", "lost", "mass drift", "escaped",
                                          "RSS growth (bytes)", "verdict"))
for ranks in (1, 2, 3, 4):
    j = json.load(open(os.path.join(out, f"soak_r{ranks}.json")))
    total = j["particles"]["field"]
    last = j["intervals"][-1]["ranks"]
    lost = total - sum(r["field"] for r in last)
    mass = j["physics"]["mass"]
    drift = max(abs(m - mass[0]) for m in mass) / mass[0]
    escaped = max(r["escaped"] for iv in j["intervals"] for r in iv["ranks"])
    growth = 0.0
    for k in range(ranks):
        rss = [iv["ranks"][k]["rss_bytes"] for iv in j["intervals"]]
        growth = max(growth, max(rss[1:]) - rss[0])
    # Flat: within 2 MiB of the first interval's resident set (allocator noise, MPI buffers).
    good = lost == 0 and drift <= 1e-12 and escaped == 0 and growth <= 2 * 1024 * 1024
    ok = ok and good
    summary["runs"].append({"ranks": ranks, "steps": j["config"]["steps"], "fluid_particles": total,
                            "lost": lost, "mass_drift_relative": drift, "escaped_max": escaped,
                            "rss_growth_bytes": growth, "wall_s": j["wall_s"], "ok": good})
    print("  %5d %9d %8d %16.3g %8d %20.0f %s" % (ranks, j["config"]["steps"], lost, drift, escaped,
                                                 growth, "ok" if good else "FAILED"))
json.dump(summary, open(os.path.join(out, "summary.json"), "w"), indent=2)
sys.exit(0 if ok else 1)
EOF
