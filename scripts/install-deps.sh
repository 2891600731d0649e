#!/usr/bin/env bash
# Installs the Debian packages sphperf needs, only those missing. Idempotent and non-interactive:
# CI and every fresh machine get their dependencies from here.
set -euo pipefail
# --with-reference-tools also installs likwid and NetPIPE, which scripts/compare-reference.py runs
# beside ours, and PySPH (with the Python headers its generated Cython needs), which
# scripts/bench-grids.py --pysph runs; they are comparison tools, not dependencies of sphperf.
# --with-fuzz also installs clang and its OpenMP runtime for the libFuzzer harnesses
# (scripts/fuzz.sh); CI does not run them.
# --with-slurm also installs Slurm (slurmctld, slurmd, srun/sbatch) and munge, for
# scripts/slurm/local-slurm.sh, a one-node Slurm on this machine for tests and demos.

packages=(
    build-essential cmake ninja-build pkg-config git
    libopenmpi-dev openmpi-bin
    libopenblas-dev
    libhwloc-dev hwloc
    nlohmann-json3-dev
    libgtest-dev
    libcli11-dev
    libgsl-dev
    python3-matplotlib
)

for arg in "$@"; do
    case "$arg" in
        --with-reference-tools) packages+=(likwid netpipe-openmpi python3-pysph python3-dev) ;;
        --with-fuzz) packages+=(clang libomp-dev) ;;
        --with-slurm) packages+=(slurm-wlm munge) ;;
        *)
            echo "install-deps: unknown argument '$arg' (expected --with-reference-tools, --with-fuzz, --with-slurm or nothing)" >&2
            exit 2
            ;;
    esac
done

missing=()
for p in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$p")
    fi
done

if [ ${#missing[@]} -eq 0 ]; then
    echo "install-deps: all dependencies present"
    exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
    sudo_cmd=(sudo)
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
