#!/usr/bin/env bash
# Runs an MPI program with the flags this machine needs, so nobody has to remember them:
#   scripts/mpirun.sh -n RANKS [-t THREADS] PROGRAM [ARGS...]
# THREADS (OpenMP threads per rank; default OMP_NUM_THREADS, else 1) is exported as
# OMP_NUM_THREADS and each rank is bound to that many cores, when RANKS x THREADS fit the
# cores; otherwise ranks are not bound and --oversubscribe is added. --allow-run-as-root is
# added when run as root. Inside a Slurm allocation (SLURM_JOB_ID) it runs srun --mpi=pmix
# with --cpus-per-task=THREADS and core binding instead (when srun offers PMIx). mpirun's own
# multi-line notices are silenced (--quiet) so a program's one-line error stays one line; set
# SPHPERF_MPIRUN_VERBOSE=1 to see them.
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

# Inside a Slurm allocation: srun with PMIx, THREADS cores per task, each task bound to its
# cores (mpirun would not know the allocation's cores). SPHPERF_NO_SRUN=1 keeps mpirun.
if [ -n "${SLURM_JOB_ID:-}" ] && [ "${SPHPERF_NO_SRUN:-0}" != 1 ] && command -v srun >/dev/null &&
    srun --mpi=list 2>&1 | grep -q pmix; then
    srun_flags=(--mpi=pmix -n "$ranks" --cpus-per-task="$threads" --cpu-bind=cores)
    # The allocation's CPUs on this node: SLURM_CPUS_ON_NODE in a batch script or step,
    # SLURM_JOB_CPUS_PER_NODE ("2" or "2(x3)") under salloc.
    allocated=${SLURM_CPUS_ON_NODE:-${SLURM_JOB_CPUS_PER_NODE:-0}}
    allocated=${allocated%%[!0-9]*}
    allocated=${allocated:-0}
    if [ "${SLURM_JOB_NUM_NODES:-1}" -eq 1 ] && [ "$allocated" -gt 0 ] &&
        [ $((ranks * threads)) -gt "$allocated" ]; then
        # More processes x threads than the allocation's cores: time-share them, unbound.
        srun_flags=(--mpi=pmix -n "$ranks" --overcommit --cpu-bind=none)
        # Open MPI cannot tell it is oversubscribed under srun (mpirun's --oversubscribe tells
        # it): without this its ranks spin while they wait and starve the rank they wait for.
        export OMPI_MCA_mpi_yield_when_idle=1
    fi
    export OMP_NUM_THREADS="$threads"
    exec srun "${srun_flags[@]}" "$@"
fi

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
