#pragma once
// The machine as hwloc sees it: summary for reports, thread placement (compact / scatter) with
// real binding, and the locality class of two processing units.
#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

struct hwloc_topology;
struct hwloc_bitmap_s;

namespace sphperf {

enum class Affinity { compact, scatter };
Affinity parse_affinity(std::string_view name); // throws UsageError on an unknown name
std::string_view to_string(Affinity a);

// Relation of two processing units, nearest first.
enum class Locality { same_core, same_l3, same_package, other_package, other_node };
std::string_view to_string(Locality l);

// Owning hwloc bitmap (a cpuset).
class CpuSet {
public:
    CpuSet();
    explicit CpuSet(const hwloc_bitmap_s *other);
    CpuSet(const CpuSet &other);
    CpuSet &operator=(const CpuSet &other);
    ~CpuSet();

    hwloc_bitmap_s *get() const { return set_; }
    std::string to_list() const; // "0", "0-3", "0,2"
    int first() const;
    int weight() const;

private:
    hwloc_bitmap_s *set_;
};

// machine: every processing unit of the node; binding: only those this process is bound to (a
// Slurm allocation, taskset), so cores(), pus() and placement() stay inside them.
enum class TopologyScope { machine, binding };

class Topology {
public:
    explicit Topology(TopologyScope scope = TopologyScope::machine);
    ~Topology();
    Topology(const Topology &) = delete;
    Topology &operator=(const Topology &) = delete;

    int packages() const;
    int cores() const;
    int pus() const;
    int numa_nodes() const;
    // Sum of the sizes of all last-level cache instances (STREAM's sizing rule).
    std::uint64_t last_level_cache_bytes() const;
    std::uint64_t memory_bytes() const;

    nlohmann::json summary() const;

    // One single-PU cpuset per thread: compact fills cores in logical order, scatter spreads
    // threads as far apart as the topology allows (hwloc_distrib). More threads than cores wrap.
    std::vector<CpuSet> placement(int threads, Affinity affinity) const;

    void bind_this_thread(const CpuSet &set) const;
    CpuSet this_thread_binding() const;
    CpuSet this_process_binding() const;
    int last_cpu_of_this_thread() const;

    // Locality of two PUs given by OS index on this node.
    Locality classify(int pu_a, int pu_b) const;

private:
    hwloc_topology *topo_;
};

} // namespace sphperf
