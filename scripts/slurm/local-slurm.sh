#!/usr/bin/env bash
# A one-node Slurm on this machine, for tests and demos:
#   scripts/slurm/local-slurm.sh start|stop|status [--dir DIR] [--nodes N]
# start writes DIR/slurm.conf for this host's cores and memory, a munge key, and starts munged,
# slurmctld and slurmd from DIR (default /tmp/sphperf-slurm, or SPHPERF_SLURM_DIR); it is
# idempotent (a running Slurm of DIR is left as it is). Clients need SLURM_CONF=DIR/slurm.conf:
# start and status print the export line. stop ends the daemons. Installs nothing:
# scripts/install-deps.sh --with-slurm does. Needs root (slurmd runs jobs as their users).
# --nodes N (N > 1) emulates N nodes on this host for multi-node scripts: N slurmd named
# HOST-n1.. on their own ports, each owning an equal share of the CPUs (pinned with taskset;
# tasks inherit it) and of the memory. Their MPI traffic still goes through this host's shared
# memory: it checks the scripts, not a network. Ports: SPHPERF_SLURMCTLD_PORT (6817) and
# SPHPERF_SLURMD_PORT (6818, the first of N).
set -euo pipefail

usage() { sed -n '2,13p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }
[ $# -ge 1 ] || usage 2
action=$1
shift
dir="${SPHPERF_SLURM_DIR:-/tmp/sphperf-slurm}"
nodes=1
while [ $# -gt 0 ]; do
    case "$1" in
        --dir) [ $# -ge 2 ] || usage 2; dir=$2; shift 2 ;;
        --nodes) [ $# -ge 2 ] || usage 2; nodes=$2; shift 2
            case "$nodes" in ''|*[!0-9]*|0) echo "local-slurm.sh: --nodes '$nodes' is not a positive integer" >&2; exit 2 ;; esac ;;
        -h|--help) usage 0 ;;
        *) echo "local-slurm.sh: unknown argument '$1' (expected --dir DIR or --nodes N)" >&2; exit 2 ;;
    esac
done
case "$action" in start|stop|status) ;; -h|--help) usage 0 ;;
    *) echo "local-slurm.sh: unknown action '$action' (expected start, stop or status)" >&2; exit 2 ;;
esac

conf="$dir/slurm.conf"
host=$(hostname -s)

pid_alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }
# The slurmd pid files of the running configuration (one per emulated node).
slurmd_pids() { compgen -G "$dir/slurmd-*.pid" || true; }
running() {
    pid_alive "$dir/munged.pid" && pid_alive "$dir/slurmctld.pid" || return 1
    local f n=0
    for f in $(slurmd_pids); do pid_alive "$f" || return 1; n=$((n + 1)); done
    [ "$n" -ge 1 ]
}

stop() {
    local f pid
    for f in $(slurmd_pids) "$dir/slurmctld.pid" "$dir/munged.pid"; do
        if pid_alive "$f"; then
            pid=$(cat "$f")
            kill "$pid" 2>/dev/null || true
            for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
            kill -9 "$pid" 2>/dev/null || true
        fi
        rm -f "$f"
    done
}

status() {
    if running; then
        echo "local-slurm: running from $dir (munged $(cat "$dir/munged.pid"), slurmctld" \
            "$(cat "$dir/slurmctld.pid"), $(slurmd_pids | wc -l) slurmd)"
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
        local have
        have=$(slurmd_pids | wc -l)
        if [ "$have" -ne "$nodes" ]; then
            echo "local-slurm.sh: a Slurm of $have node(s) already runs from $dir; stop it" \
                "before starting $nodes" >&2
            exit 2
        fi
        status
        return 0
    fi
    stop # half-started daemons of an earlier attempt
    mkdir -p "$dir"/{state,log,munge}
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
    [ "$nodes" -le "$cpus" ] || {
        echo "local-slurm.sh: --nodes $nodes needs at least $nodes CPUs, this machine has $cpus" >&2
        exit 2
    }
    # One node: this host as it is. Several: HOST-n1.. each with an equal CPU and memory share,
    # bound by taskset (task/none: Slurm would bind every node's tasks to its own CPU 0).
    local names=() node_lines="" task=task/affinity slurmd_port=${SPHPERF_SLURMD_PORT:-6818} i
    if [ "$nodes" -eq 1 ]; then
        names=("$host")
        node_lines="NodeName=$host Sockets=$sockets CoresPerSocket=$cores_per ThreadsPerCore=$threads_per RealMemory=$mem_mb State=UNKNOWN"
    else
        task=task/none
        for i in $(seq "$nodes"); do
            names+=("$host-n$i")
            node_lines+="NodeName=$host-n$i NodeHostname=$host NodeAddr=127.0.0.1 Port=$((slurmd_port + i - 1)) CPUs=$((cpus / nodes)) RealMemory=$((mem_mb / nodes)) State=UNKNOWN"$'\n'
        done
    fi
    for i in "${names[@]}"; do mkdir -p "$dir/tmp-$i" "$dir/spool-$i"; done
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
SlurmdSpoolDir=$dir/spool-%n
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd-%n.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd-%n.log
SlurmctldPort=${SPHPERF_SLURMCTLD_PORT:-6817}
SlurmdPort=$slurmd_port
# Per node: emulated nodes on one host must not share PMIx's client directories.
TmpFS=$dir/tmp-%n
ProctrackType=proctrack/linuxproc
TaskPlugin=$task
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
$node_lines
PartitionName=local Nodes=$(IFS=,; echo "${names[*]}") Default=YES MaxTime=INFINITE State=UP
EOF
    munged --key-file="$dir/munge/munge.key" --socket="$dir/munge/munge.socket" \
        --pid-file="$dir/munged.pid" --log-file="$dir/log/munged.log" \
        --seed-file="$dir/munge/munge.seed" --force
    slurmctld -f "$conf"
    if [ "$nodes" -eq 1 ]; then
        slurmd -f "$conf" -N "$host"
    else
        local per=$((cpus / nodes)) online
        mapfile -t online < <(lscpu -p=CPU | grep -v '^#')
        for i in $(seq "$nodes"); do
            taskset -c "$(IFS=,; echo "${online[*]:$(((i - 1) * per)):$per}")" \
                slurmd -f "$conf" -N "$host-n$i"
        done
    fi
    # Up when every node answers idle (or mixed/allocated: jobs of an earlier start).
    for _ in $(seq 100); do
        if [ "$(SLURM_CONF="$conf" sinfo -h -N -o %T 2>/dev/null |
            grep -Ec '^(idle|mixed|allocated)')" -eq "$nodes" ]; then
            status
            return 0
        fi
        sleep 0.2
    done
    echo "local-slurm.sh: the nodes did not come up within 20 s; see $dir/log/" >&2
    tail -n 3 "$dir"/log/*.log >&2 || true
    exit 1
}

case "$action" in
    start) start ;;
    stop) stop; echo "local-slurm: stopped ($dir)" ;;
    status) status ;;
esac
