#include "sphperf/topology.hpp"

#include "sphperf/errors.hpp"

#include <hwloc.h>
#include <unistd.h>

#include <climits>
#include <fstream>
#include <stdexcept>

namespace sphperf {

Affinity parse_affinity(std::string_view name) {
    if (name == "compact")
        return Affinity::compact;
    if (name == "scatter")
        return Affinity::scatter;
    throw UsageError("unknown affinity '" + std::string(name) + "', expected compact or scatter");
}

std::string_view to_string(Affinity a) {
    return a == Affinity::compact ? "compact" : "scatter";
}

std::string_view to_string(Locality l) {
    switch (l) {
    case Locality::same_core:
        return "same_core";
    case Locality::same_l3:
        return "same_l3";
    case Locality::same_package:
        return "same_package";
    case Locality::other_package:
        return "other_package";
    case Locality::other_node:
        return "other_node";
    }
    return "unknown";
}

CpuSet::CpuSet() : set_(hwloc_bitmap_alloc()) {}
CpuSet::CpuSet(const hwloc_bitmap_s *other) : set_(hwloc_bitmap_dup(other)) {}
CpuSet::CpuSet(const CpuSet &other) : set_(hwloc_bitmap_dup(other.set_)) {}
CpuSet &CpuSet::operator=(const CpuSet &other) {
    if (this != &other)
        hwloc_bitmap_copy(set_, other.set_);
    return *this;
}
CpuSet::~CpuSet() {
    hwloc_bitmap_free(set_);
}

std::string CpuSet::to_list() const {
    char *s = nullptr;
    hwloc_bitmap_list_asprintf(&s, set_);
    std::string out = s ? s : "";
    free(s);
    return out;
}
int CpuSet::first() const {
    return hwloc_bitmap_first(set_);
}
int CpuSet::weight() const {
    return hwloc_bitmap_weight(set_);
}

Topology::Topology(TopologyScope scope) {
    if (hwloc_topology_init(&topo_) != 0 || hwloc_topology_load(topo_) != 0)
        throw std::runtime_error("hwloc could not load the machine topology");
    if (scope == TopologyScope::binding) {
        const CpuSet bound = this_process_binding();
        // A process bound nowhere in particular (or to everything) sees the whole machine.
        if (bound.weight() > 0 &&
            !hwloc_bitmap_isincluded(hwloc_topology_get_topology_cpuset(topo_), bound.get()) &&
            hwloc_topology_restrict(topo_, bound.get(), 0) != 0) {
            hwloc_topology_destroy(topo_);
            throw std::runtime_error("hwloc could not restrict the topology to this process's "
                                     "cpuset " +
                                     bound.to_list());
        }
    }
}
Topology::~Topology() {
    hwloc_topology_destroy(topo_);
}

int Topology::packages() const {
    return hwloc_get_nbobjs_by_type(topo_, HWLOC_OBJ_PACKAGE);
}
int Topology::cores() const {
    return hwloc_get_nbobjs_by_type(topo_, HWLOC_OBJ_CORE);
}
int Topology::pus() const {
    return hwloc_get_nbobjs_by_type(topo_, HWLOC_OBJ_PU);
}
int Topology::numa_nodes() const {
    return hwloc_get_nbobjs_by_type(topo_, HWLOC_OBJ_NUMANODE);
}

namespace {
std::uint64_t cache_size(hwloc_topology_t topo, hwloc_obj_type_t type) {
    hwloc_obj_t obj = hwloc_get_obj_by_type(topo, type, 0);
    return obj && obj->attr ? obj->attr->cache.size : 0;
}
int cache_count(hwloc_topology_t topo, hwloc_obj_type_t type) {
    return hwloc_get_nbobjs_by_type(topo, type);
}

std::string cpu_model(hwloc_topology_t topo) {
    hwloc_obj_t pkg = hwloc_get_obj_by_type(topo, HWLOC_OBJ_PACKAGE, 0);
    if (pkg)
        if (const char *m = hwloc_obj_get_info_by_name(pkg, "CPUModel"))
            return m;
    return "unknown";
}
} // namespace

std::uint64_t Topology::last_level_cache_bytes() const {
    for (auto type : {HWLOC_OBJ_L3CACHE, HWLOC_OBJ_L2CACHE, HWLOC_OBJ_L1CACHE}) {
        const int n = cache_count(topo_, type);
        if (n > 0)
            return cache_size(topo_, type) * static_cast<std::uint64_t>(n);
    }
    return 0;
}

std::uint64_t Topology::memory_bytes() const {
    // The OS figure: hwloc's NUMA memory can under-report on some virtual machines.
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    if (pages > 0 && page > 0)
        return static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(page);
    return hwloc_get_root_obj(topo_)->total_memory;
}

nlohmann::json Topology::summary() const {
    nlohmann::json caches = nlohmann::json::object();
    const std::pair<hwloc_obj_type_t, const char *> levels[] = {
        {HWLOC_OBJ_L1CACHE, "L1d"}, {HWLOC_OBJ_L2CACHE, "L2"}, {HWLOC_OBJ_L3CACHE, "L3"}};
    for (auto [type, name] : levels) {
        const int n = cache_count(topo_, type);
        if (n > 0)
            caches[name] = {{"size_bytes", cache_size(topo_, type)}, {"instances", n}};
    }
    return {{"cpu_model", cpu_model(topo_)},
            {"packages", packages()},
            {"numa_nodes", numa_nodes()},
            {"cores", cores()},
            {"pus", pus()},
            {"caches", caches},
            {"last_level_cache_bytes", last_level_cache_bytes()},
            {"memory_bytes", memory_bytes()}};
}

std::vector<CpuSet> Topology::placement(int threads, Affinity affinity) const {
    const int ncores = std::max(cores(), 1);
    std::vector<CpuSet> sets(static_cast<std::size_t>(threads));
    if (affinity == Affinity::compact) {
        for (int t = 0; t < threads; ++t) {
            hwloc_obj_t core = hwloc_get_obj_by_type(topo_, HWLOC_OBJ_CORE, t % ncores);
            hwloc_bitmap_copy(sets[t].get(), core->cpuset);
        }
    } else {
        // hwloc_distrib spreads n sets across the tree, packages and caches first; it allocates
        // the sets itself.
        std::vector<hwloc_bitmap_t> raw(static_cast<std::size_t>(threads), nullptr);
        hwloc_obj_t root = hwloc_get_root_obj(topo_);
        if (hwloc_distrib(topo_, &root, 1, raw.data(), static_cast<unsigned>(threads), INT_MAX,
                          0) != 0)
            throw std::runtime_error("hwloc_distrib failed");
        for (int t = 0; t < threads; ++t) {
            hwloc_bitmap_copy(sets[t].get(), raw[t]);
            hwloc_bitmap_free(raw[t]);
        }
    }
    for (auto &s : sets)
        hwloc_bitmap_singlify(s.get()); // one PU each, so SMT siblings never share a thread
    return sets;
}

void Topology::bind_this_thread(const CpuSet &set) const {
    if (hwloc_set_cpubind(topo_, set.get(), HWLOC_CPUBIND_THREAD) != 0)
        throw std::runtime_error("hwloc could not bind a thread to cpuset " + set.to_list());
}

CpuSet Topology::this_thread_binding() const {
    CpuSet s;
    hwloc_get_cpubind(topo_, s.get(), HWLOC_CPUBIND_THREAD);
    return s;
}

CpuSet Topology::this_process_binding() const {
    CpuSet s;
    hwloc_get_cpubind(topo_, s.get(), HWLOC_CPUBIND_PROCESS);
    return s;
}

int Topology::last_cpu_of_this_thread() const {
    CpuSet s;
    if (hwloc_get_last_cpu_location(topo_, s.get(), HWLOC_CPUBIND_THREAD) != 0)
        return -1;
    return s.first();
}

Locality Topology::classify(int pu_a, int pu_b) const {
    hwloc_obj_t a = hwloc_get_pu_obj_by_os_index(topo_, static_cast<unsigned>(pu_a));
    hwloc_obj_t b = hwloc_get_pu_obj_by_os_index(topo_, static_cast<unsigned>(pu_b));
    if (!a || !b)
        throw std::runtime_error("unknown processing unit index");
    auto ancestor = [&](hwloc_obj_t pu, hwloc_obj_type_t type) {
        return hwloc_get_ancestor_obj_by_type(topo_, type, pu);
    };
    if (ancestor(a, HWLOC_OBJ_CORE) == ancestor(b, HWLOC_OBJ_CORE))
        return Locality::same_core;
    hwloc_obj_t l3a = ancestor(a, HWLOC_OBJ_L3CACHE);
    if (l3a && l3a == ancestor(b, HWLOC_OBJ_L3CACHE))
        return Locality::same_l3;
    hwloc_obj_t pa = ancestor(a, HWLOC_OBJ_PACKAGE);
    if (pa && pa == ancestor(b, HWLOC_OBJ_PACKAGE))
        return Locality::same_package;
    return Locality::other_package;
}

} // namespace sphperf
