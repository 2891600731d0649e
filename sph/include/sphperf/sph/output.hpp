#pragma once
// What a run shows a person: the progress line, ParaView snapshots and the JSON report.
#include "sphperf/sph/particles.hpp"
#include "sphperf/sph/record.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <vector>

namespace sphperf {
class Topology;
}

namespace sphperf::sph {

// "step, simulated time, steps/s, ETA" on stderr, redrawn at most twice a second; silent when
// stderr is not a terminal or when disabled.
class Progress {
public:
    Progress(bool enabled, std::int64_t steps, double dt);
    void update(std::int64_t step);
    void finish();

private:
    bool enabled_;
    std::int64_t steps_;
    double dt_, start_, last_ = 0;
    bool drawn_ = false;
};

// One .vtu per rank and snapshot (owned particles: position, velocity, density, pressure, kind,
// owning rank) and a .pvd index ordering them in time.
// One rank's owned particles as a ParaView .vtu file (positions, velocity, density, pressure,
// rank, kind, id).
void write_vtu(const std::filesystem::path &path, const Particles &p, int rank);

class Snapshots {
public:
    void write(const std::filesystem::path &dir, std::int64_t index, double time,
               const Particles &p, int rank, int ranks);
    void write_index(const std::filesystem::path &dir) const;

private:
    struct Entry {
        double time;
        int part;
        std::string file;
    };
    std::vector<Entry> entries_;
};

nlohmann::json build_report(const RunRecord &run, const Topology &topo);

} // namespace sphperf::sph
