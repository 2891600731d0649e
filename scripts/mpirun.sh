#!/usr/bin/env bash
# Runs an MPI program with the flags this machine needs, so nobody has to remember them:
#   scripts/mpirun.sh -n RANKS [-t THREADS] PROGRAM [ARGS...]
# THREADS (OpenMP threads per rank; default OMP_NUM_THREADS, else 1) is exported as
# OMP_NUM_THREADS and each rank is bound to that many cores, when RANKS x THREADS fit the
# cores; above them --oversubscribe is added and one-thread ranks are bound round-robin to the
# cores (rank r on core r mod cores), ranks of more threads not at all. --allow-run-as-root is
# added when run as root. Inside a Slurm allocation (SLURM_JOB_ID) it runs srun --mpi=pmix
# with --cpus-per-task=THREADS and core binding instead (when srun offers PMIx). mpirun's own
# multi-line notices are silenced (--quiet) so a program's one-line error stays one line; set
# SPHPERF_MPIRUN_VERBOSE=1 to see them. Open MPI's shared-memory eager limit is raised to 256 KB
# unless OMPI_MCA_btl_vader_eager_limit is set, and on a node without RDMA devices the pml is
# ob1 unless OMPI_MCA_pml is set (below).
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

# Open MPI's shared-memory transport copies a message up to its eager limit (4 KB by default)
# through shared buffers, a larger one by a single copy the receiver makes with
# process_vm_readv (CMA). On this VM CMA is the slow path: a 16 KB shift took 5.5 us back to
# back and 12.5 us after 10 ms of compute, 1.2 and 4.1 us with this limit; the still tank's
# 70 KB ghosts at scale 4 took 36-46 us to complete, 9-11 with a 128 KB limit (sph/NOTES.md,
# "Overlap"). The app's messages fit below it. A value set by the user wins; reports record it
# (mpi_mca).
export OMPI_MCA_btl_vader_eager_limit="${OMPI_MCA_btl_vader_eager_limit:-262144}"
# When a rank exits non-zero, mpirun signals the others and by default waits a second per
# signal for them to die: every error exit (a bad option, a fault on one rank) took 2.0-2.4 s
# instead of 0.05-0.4 s (`mpirun -n 1 sh -c 'exit 2'`: 2.06 against 0.04 s). No program here
# handles SIGTERM, so the grace period buys nothing. A value set by the user wins.
export OMPI_MCA_odls_base_sigkill_timeout="${OMPI_MCA_odls_base_sigkill_timeout:-0}"
# Every process start probes UCX for Open MPI's point-to-point layer (pml), which on a node
# without RDMA devices declines, and ob1 (shared memory, TCP) is chosen anyway: the probe took
# 0.20 of the 0.31 s that MPI_Init alone takes here, on every launch (about 80 launches in the
# main job). Where /sys/class/infiniband lists no device, ask for ob1 directly; a node with
# RDMA devices keeps the probe (and UCX). A value set by the user wins; reports record it.
if [ -z "${OMPI_MCA_pml:-}" ] && [ -z "$(ls -A /sys/class/infiniband 2>/dev/null)" ]; then
    export OMPI_MCA_pml=ob1
fi

# Inside a Slurm allocation: srun with PMIx, THREADS cores per task, each task bound to its
# cores (mpirun would not know the allocation's cores). SPHPERF_NO_SRUN=1 keeps mpirun.
if [ -n "${SLURM_JOB_ID:-}" ] && [ "${SPHPERF_NO_SRUN:-0}" != 1 ] && command -v srun >/dev/null &&
    srun --mpi=list 2>&1 | grep -q pmix; then
    srun_flags=(--mpi=pmix -n "$ranks" --cpus-per-task="$threads" --cpu-bind=cores)
    # A cluster without a task plugin cannot bind (local-slurm.sh's emulated nodes pin their
    # slurmd instead): ask for no binding rather than draw srun's warning on every launch.
    if scontrol show config 2>/dev/null | grep -Eq '^TaskPlugin +=.*task/none'; then
        srun_flags=(--mpi=pmix -n "$ranks" --cpus-per-task="$threads")
    fi
    # The allocation's CPUs on this node: SLURM_CPUS_ON_NODE in a batch script or step,
    # SLURM_JOB_CPUS_PER_NODE ("2" or "2(x3)") under salloc.
    allocated=${SLURM_CPUS_ON_NODE:-${SLURM_JOB_CPUS_PER_NODE:-0}}
    allocated=${allocated%%[!0-9]*}
    allocated=${allocated:-0}
    if [ "${SLURM_JOB_NUM_NODES:-1}" -eq 1 ] && [ "$allocated" -gt 0 ] &&
        [ $((ranks * threads)) -gt "$allocated" ]; then
        # More processes x threads than the allocation's cores: time-share them, one-thread
        # ranks bound round-robin to the allocation's CPUs as mpirun binds them below.
        srun_flags=(--mpi=pmix -n "$ranks" --overcommit --cpu-bind=none)
        if [ "$threads" -eq 1 ]; then
            cpus=$(python3 -c 'import os; print(",".join(map(str, sorted(os.sched_getaffinity(0)))))')
            srun_flags=(--mpi=pmix -n "$ranks" --overcommit --cpu-bind="map_cpu:$cpus")
        fi
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
if [ $((ranks * threads)) -gt "$cores" ] && [ "$threads" -eq 1 ]; then
    # Above the cores one-thread ranks are bound round-robin (rank r on core r mod cores): left
    # to the scheduler, two busy neighbours shared a core in some runs and not in others (the
    # 4-rank dam break took 3.4-6.1 s unbound, 3.4-4.1 s bound; model/NOTES.md), and the model
    # predicts where they are.
    flags+=(--oversubscribe --map-by core --bind-to core:overload-allowed)
    export OMPI_MCA_mpi_yield_when_idle=1 # a waiting rank gives its core to the one it waits for
elif [ $((ranks * threads)) -gt "$cores" ]; then
    flags+=(--oversubscribe --bind-to none)
else
    flags+=(--map-by "slot:PE=$threads" --bind-to core)
fi
export OMP_NUM_THREADS="$threads"
exec mpirun "${flags[@]}" -x OMP_NUM_THREADS -n "$ranks" "$@"
