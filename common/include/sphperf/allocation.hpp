#pragma once
// What this process may use of the node, as the launcher and Slurm say and as it is bound, so
// sph and the benchmarks take their default thread counts from the allocation rather than from
// the whole machine (a 2-rank srun on a 2-core node must not start 2 threads per rank).
#include "sphperf/topology.hpp"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace sphperf {

// Leading integer of an environment variable ("2(x3)" gives 2); 0 when unset or not a number.
int env_count(const char *name);

// This job's ranks on this node, as the launcher (mpirun or srun) tells them; 1 outside one.
int ranks_on_node();

// Threads per rank when nothing else says: a Slurm task's own CPUs (SLURM_CPUS_PER_TASK); else
// the cores this process is bound to, shared fairly by the node's ranks when the launcher bound
// none of them apart (every rank then sees the whole node or allocation).
int default_threads(const Topology &topo);

// Cores a single-process benchmark may use: those of `topo` (build it with
// TopologyScope::binding so they are the ones this process is bound to), at most
// SLURM_CPUS_PER_TASK when that is set.
int usable_cores(const Topology &topo);

// Refuses (UsageError) a --threads entry outside 1..the processing units of `topo`, naming
// them; warns on stderr for one above SLURM_CPUS_PER_TASK (the threads would take turns).
void check_thread_counts(const std::vector<int> &threads, const Topology &topo,
                         const char *program);

// Where this process may run, for its report: bound PUs, usable cores, Slurm's CPUs per task.
nlohmann::json allocation_summary(const Topology &topo);

// The node this process runs on as the scheduler names it (SLURMD_NODENAME), else the host name:
// two slurmd nodes emulated on one host are two nodes, and on a cluster the names agree.
std::string node_name();

} // namespace sphperf
