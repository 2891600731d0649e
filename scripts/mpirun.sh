#!/usr/bin/env bash
# Runs an MPI program with the flags this machine needs, so nobody has to remember them:
#   scripts/mpirun.sh -n RANKS [-t THREADS] PROGRAM [ARGS...]
# THREADS (OpenMP threads per rank; default OMP_NUM_THREADS, else 1) is exported as
# OMP_NUM_THREADS and each rank is bound to that many cores, when RANKS x THREADS fit the
# cores; otherwise ranks are not bound and --oversubscribe is added. --allow-run-as-root is
# added when run as root. mpirun's own multi-line notices are silenced (--quiet) so a program's
# one-line error stays one line; set SPHPERF_MPIRUN_VERBOSE=1 to see them.
set -euo pipefail

usage() { echo "usage: $(basename "$0") -n RANKS [-t THREADS] PROGRAM [ARGS...]" >&2; exit 2; }
positive() {
    case "$2" in
        ''|*[!0-9]*|0) echo "mpirun.sh: $1 '$2' is not a positive integer" >&2; exit 2 ;;
    esac
}

ranks=""
threads="${OMP_NUM_THREADS:-1}"
while [ $# -gt 0 ]; do
    case "$1" in
        -n|-np) [ $# -ge 2 ] || usage; ranks="$2"; shift 2 ;;
        -t) [ $# -ge 2 ] || usage; threads="$2"; shift 2 ;;
        *) break ;;
    esac
done
[ -n "$ranks" ] && [ $# -ge 1 ] || usage
positive "rank count" "$ranks"
positive "thread count" "$threads"

command -v mpirun >/dev/null || { echo "mpirun.sh: mpirun not found; run scripts/install-deps.sh" >&2; exit 1; }

cores=$(nproc)
flags=()
if [ "${SPHPERF_MPIRUN_VERBOSE:-0}" != 1 ]; then
    flags+=(--quiet)
fi
if [ "$(id -u)" -eq 0 ]; then
    flags+=(--allow-run-as-root)
fi
if [ $((ranks * threads)) -gt "$cores" ]; then
    flags+=(--oversubscribe --bind-to none)
else
    flags+=(--map-by "slot:PE=$threads" --bind-to core)
fi
export OMP_NUM_THREADS="$threads"
exec mpirun "${flags[@]}" -x OMP_NUM_THREADS -n "$ranks" "$@"
