#!/usr/bin/env bash
# A one-node Slurm on this machine, for tests and demos:
#   scripts/slurm/local-slurm.sh start|stop|status [--dir DIR]
# start writes DIR/slurm.conf for this host's cores and memory, a munge key, and starts munged,
# slurmctld and slurmd from DIR (default /tmp/sphperf-slurm, or SPHPERF_SLURM_DIR); it is
# idempotent (a running Slurm of DIR is left as it is). Clients need SLURM_CONF=DIR/slurm.conf:
# start and status print the export line. stop ends the three daemons. Installs nothing:
# scripts/install-deps.sh --with-slurm does. Needs root (slurmd runs jobs as their users).
set -euo pipefail

usage() { sed -n '2,8p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }
[ $# -ge 1 ] || usage 2
action=$1
shift
dir="${SPHPERF_SLURM_DIR:-/tmp/sphperf-slurm}"
while [ $# -gt 0 ]; do
    case "$1" in
        --dir) [ $# -ge 2 ] || usage 2; dir=$2; shift 2 ;;
        -h|--help) usage 0 ;;
        *) echo "local-slurm.sh: unknown argument '$1' (expected --dir DIR)" >&2; exit 2 ;;
    esac
done
case "$action" in start|stop|status) ;; -h|--help) usage 0 ;;
    *) echo "local-slurm.sh: unknown action '$action' (expected start, stop or status)" >&2; exit 2 ;;
esac

conf="$dir/slurm.conf"
host=$(hostname -s)

pid_alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }
running() { pid_alive "$dir/munged.pid" && pid_alive "$dir/slurmctld.pid" && pid_alive "$dir/slurmd.pid"; }

stop() {
    local d pid
    for d in slurmd slurmctld munged; do
        if pid_alive "$dir/$d.pid"; then
            pid=$(cat "$dir/$d.pid")
            kill "$pid" 2>/dev/null || true
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            kill -9 "$pid" 2>/dev/null || true
        fi
        rm -f "$dir/$d.pid"
    done
}

status() {
    if running; then
        echo "local-slurm: running from $dir (munged $(cat "$dir/munged.pid"), slurmctld" \
            "$(cat "$dir/slurmctld.pid"), slurmd $(cat "$dir/slurmd.pid"))"
        SLURM_CONF="$conf" sinfo -N -o "  node %N: %T, %c CPUs, %m MB" 2>&1 | tail -n +2
        echo "export SLURM_CONF=$conf"
        return 0
    fi
    echo "local-slurm: not running (from $dir)"
    return 1
}

start() {
    local cmd
    for cmd in munged mungekey slurmctld slurmd sinfo scontrol; do
        command -v "$cmd" >/dev/null || {
            echo "local-slurm.sh: '$cmd' not found; run scripts/install-deps.sh --with-slurm" >&2
            exit 2
        }
    done
    [ "$(id -u)" -eq 0 ] || { echo "local-slurm.sh: needs root (slurmd starts jobs as their users)" >&2; exit 2; }
    if running; then
        status
        return 0
    fi
    stop # half-started daemons of an earlier attempt
    mkdir -p "$dir"/{state,spool,log,munge}
    chmod 700 "$dir/munge"
    [ -f "$dir/munge/munge.key" ] || mungekey --create --keyfile="$dir/munge/munge.key" >/dev/null
    chmod 400 "$dir/munge/munge.key"
    # The node as Slurm will see it: this machine's sockets, cores and threads, and its memory
    # less 1 GiB for the system (slurmd refuses a node that reports less than configured).
    local sockets cores_per threads_per mem_mb cpus
    sockets=$(lscpu -p=SOCKET | grep -v '^#' | sort -u | wc -l)
    cpus=$(nproc --all)
    threads_per=$(lscpu | awk -F: '/Thread\(s\) per core/ {gsub(/ /, "", $2); print $2}')
    threads_per=${threads_per:-1}
    cores_per=$((cpus / sockets / threads_per))
    mem_mb=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024))
    local mpi=none
    [ -n "$(find /usr/lib -path '*slurm*' -name 'mpi_pmix*.so' 2>/dev/null | head -1)" ] && mpi=pmix
    cat >"$conf" <<EOF
# Written by scripts/slurm/local-slurm.sh: a one-node Slurm for tests and demos.
ClusterName=sphperf
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldPort=${SPHPERF_SLURMCTLD_PORT:-6817}
SlurmdPort=${SPHPERF_SLURMD_PORT:-6818}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/affinity
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SchedulerType=sched/backfill
MpiDefault=$mpi
ReturnToService=2
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
SlurmdTimeout=30
InactiveLimit=0
KillWait=5
NodeName=$host Sockets=$sockets CoresPerSocket=$cores_per ThreadsPerCore=$threads_per RealMemory=$mem_mb State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
    munged --key-file="$dir/munge/munge.key" --socket="$dir/munge/munge.socket" \
        --pid-file="$dir/munged.pid" --log-file="$dir/log/munged.log" \
        --seed-file="$dir/munge/munge.seed" --force
    slurmctld -f "$conf"
    slurmd -f "$conf"
    # Up when the node answers idle (or mixed/allocated: jobs of an earlier start).
    for _ in $(seq 100); do
        if SLURM_CONF="$conf" sinfo -h -N -o %T 2>/dev/null | grep -Eq '^(idle|mixed|allocated)'; then
            status
            return 0
        fi
        sleep 0.2
    done
    echo "local-slurm.sh: the node did not come up within 20 s; see $dir/log/" >&2
    tail -n 3 "$dir"/log/*.log >&2 || true
    exit 1
}

case "$action" in
    start) start ;;
    stop) stop; echo "local-slurm: stopped ($dir)" ;;
    status) status ;;
esac
