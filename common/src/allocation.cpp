#include "sphperf/allocation.hpp"

#include "sphperf/errors.hpp"
#include "sphperf/report.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace sphperf {

int env_count(const char *name) {
    const char *v = std::getenv(name);
    return v ? std::max(0, std::atoi(v)) : 0;
}

int ranks_on_node() {
    return std::max(
        {1, env_count("OMPI_COMM_WORLD_LOCAL_SIZE"), env_count("SLURM_STEP_TASKS_PER_NODE")});
}

int default_threads(const Topology &topo) {
    if (const int per_task = env_count("SLURM_CPUS_PER_TASK"); per_task > 0)
        return per_task;
    const int bound = topo.this_process_binding().weight();
    const int local = ranks_on_node();
    if (bound <= 0)
        return std::max(1, topo.pus() / local);
    return bound < topo.pus() ? bound : std::max(1, bound / local);
}

int usable_cores(const Topology &topo) {
    const int cores = std::max(1, topo.cores());
    const int per_task = env_count("SLURM_CPUS_PER_TASK");
    return per_task > 0 ? std::min(cores, per_task) : cores;
}

void check_thread_counts(const std::vector<int> &threads, const Topology &topo,
                         const char *program) {
    const int pus = std::max(1, topo.pus());
    const int per_task = env_count("SLURM_CPUS_PER_TASK");
    for (int t : threads) {
        if (t < 1 || t > pus)
            throw UsageError("--threads " + std::to_string(t) + " is outside 1.." +
                             std::to_string(pus) + " (the processing units this process may use: " +
                             topo.this_process_binding().to_list() + ")");
        if (per_task > 0 && t > per_task)
            std::fprintf(stderr,
                         "%s: warning: --threads %d exceeds SLURM_CPUS_PER_TASK=%d; the threads "
                         "take turns on the allocated cores\n",
                         program, t, per_task);
    }
}

nlohmann::json allocation_summary(const Topology &topo) {
    const int per_task = env_count("SLURM_CPUS_PER_TASK");
    return {{"node", node_name()},
            {"bound_pus", topo.this_process_binding().to_list()},
            {"usable_cores", usable_cores(topo)},
            {"slurm_cpus_per_task", per_task > 0 ? nlohmann::json(per_task) : nlohmann::json()}};
}

std::string node_name() {
    const char *slurm = std::getenv("SLURMD_NODENAME");
    return slurm && *slurm ? std::string(slurm) : hostname();
}

} // namespace sphperf
