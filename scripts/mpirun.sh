#!/usr/bin/env bash
# Runs an MPI program with the flags this machine needs, so nobody has to remember them:
#   scripts/mpirun.sh -n RANKS PROGRAM [ARGS...]
# Adds --allow-run-as-root when run as root, and --oversubscribe (no binding) only when RANKS
# exceeds the cores; otherwise ranks are bound to cores so ping-pong locality is meaningful.
# mpirun's own multi-line notices are silenced (--quiet) so a program's one-line error stays one
# line; set SPHPERF_MPIRUN_VERBOSE=1 to see them when diagnosing a launch problem.
set -euo pipefail

usage() { echo "usage: $(basename "$0") -n RANKS PROGRAM [ARGS...]" >&2; exit 2; }

ranks=""
if [ "${1:-}" = "-n" ] || [ "${1:-}" = "-np" ]; then
    ranks="${2:-}"
    shift 2 || usage
fi
[ -n "$ranks" ] && [ $# -ge 1 ] || usage
case "$ranks" in
    ''|*[!0-9]*) echo "mpirun.sh: rank count '$ranks' is not a positive integer" >&2; exit 2 ;;
esac
[ "$ranks" -ge 1 ] || { echo "mpirun.sh: rank count '$ranks' is not a positive integer" >&2; exit 2; }

command -v mpirun >/dev/null || { echo "mpirun.sh: mpirun not found; run scripts/install-deps.sh" >&2; exit 1; }

cores=$(nproc)
flags=()
if [ "${SPHPERF_MPIRUN_VERBOSE:-0}" != 1 ]; then
    flags+=(--quiet)
fi
if [ "$(id -u)" -eq 0 ]; then
    flags+=(--allow-run-as-root)
fi
if [ "$ranks" -gt "$cores" ]; then
    flags+=(--oversubscribe --bind-to none)
else
    flags+=(--bind-to core)
fi
exec mpirun "${flags[@]}" -n "$ranks" "$@"
