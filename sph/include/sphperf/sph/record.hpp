#pragma once
// What a run measured, gathered on rank 0: the input of the JSON report.
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/timers.hpp"

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace sphperf::sph {

// One rank over one report interval. Counts are means per step unless noted.
struct RankInterval {
    double steps = 0;
    double field = 0;          // fluid particles owned at the end of the interval
    double virtual_ = 0;       // mirror particles made (mirror) or wall particles owned (fixed)
    double ghost = 0;          // ghost particles received
    double pairs = 0;          // unordered interacting pairs found
    double interactions = 0;   // ordered pairs (i, j) contributing to an owned particle i
    double exported = 0;       // particles sent as ghosts
    double migrated = 0;       // particles that left this rank, total over the interval
    double cell_moves = 0;     // particles (re)filed in a cell
    double idle_s = 0;         // time with no fluid particle to work on
    double escaped = 0;        // fluid particles outside the tank (through a wall or the floor)
    double reflected = 0;      // mirror boundary: particles reflected back at a wall, total
    double field_mean = 0;     // fluid particles owned, mean over the interval's steps
    double messages = 0;       // MPI messages sent, total (counts and payloads)
    double message_bytes = 0;  // their payload bytes, total
    double comm_predict_s = 0; // predicted time of those transfers (sph --machine), total;
                               // above the cores the step replayed (sph/README.md)
    double comm_predict_exchange_s = 0; // ... by the exchange benchmark alone (the inline
                                        // prediction before session 40), total
    double comm_hockney_s = 0;          // ... by ping-pong Hockney alone (thesis T_COMM_PREDICT)
    double descents = 0;         // neighbours found right after one of larger id (id sort work):
                                 // grows as the particles' memory order decays; 0 for sorted
    double rss_bytes = 0;        // resident set size at the interval's end (soak: stays flat)
    double overlap_s = 0;        // --overlap: compute run while ghost transfers were in flight
    double hidden_predict_s = 0; // ... and the predicted transfer time it hid (T_overlap)
    double probe_shift_s = 0;    // the latency probe at the interval's end (Domain), 0: none
    double gauge_cpu_s = 0;      // the speed gauge's samples (gauge.hpp): CPU seconds, total
    double gauge_samples = 0;    // ... and how many
    // Ranks of two or more threads: the core latency gauge's readings (gauge.hpp), the median
    // round trip of a line between threads 0 and 1 per sample, total, and how many samples
    // gave one (none above the cores, where the partner thread is not running).
    double core_round_trip_s = 0;
    double core_round_trip_samples = 0;
    std::array<double, static_cast<std::size_t>(Phase::count)> timers{};
    ShiftTimes shift_comm_s{};    // comm_s split by exchange (migration, ghosts, densities)
    ShiftTimes shift_predict_s{}; // comm_predict_s split the same way
    ShiftTimes shift_predict_own_kind_s{}; // ... by the rule before session 32 (domain.hpp)
    ShiftTimes segment_cpu_s{};            // CPU time before each blocking shift, total (CommTally)
    // comm_s of the ghost and density exchanges (the ones --overlap overlaps)
    double halo_comm_s() const {
        return shift_comm_s[static_cast<std::size_t>(Shift::ghosts)] +
               shift_comm_s[static_cast<std::size_t>(Shift::densities)];
    }

    static constexpr std::size_t fields =
        27 + static_cast<std::size_t>(Phase::count) + 4 * static_cast<std::size_t>(Shift::count);
    std::array<double, fields> pack() const;
    static RankInterval unpack(const double *v);
};

static_assert(sizeof(RankInterval) == RankInterval::fields * sizeof(double),
              "RankInterval must hold exactly `fields` doubles: update `fields`");

struct IntervalRecord {
    std::int64_t step = 0;
    double time_s = 0;
    std::vector<double> columns; // fluid particles per global cell column
    std::vector<RankInterval> ranks;
    // Stored-list grids: per global cell column, the owned particles' interactions and
    // descents filed there (means per step, all ranks); empty for Cell+Sorted.
    std::vector<double> column_interactions, column_descents;
};

struct PhysicsSeries {
    std::vector<double> time_s, front_x, mass, kinetic_energy;
};

// One re-cut of the balanced decomposition (the fresh run's first cut has step 0).
struct RebalanceRecord {
    std::int64_t step = 0;
    std::vector<int> cuts;       // first column of every rank, then the column count
    double moved = 0;            // particles that changed rank, all ranks
    double seconds = 0;          // slowest rank's time for the re-cut and its migrations
    double imbalance_before = 1; // largest slab cost / mean, under the old cuts
    double imbalance_after = 1;  // and under the new ones
};

struct RunRecord {
    Config config;
    Geometry geometry;
    int ranks = 1;
    int threads = 1;
    std::int64_t steps = 0;
    std::int64_t fluid_particles = 0;
    std::int64_t wall_particles = 0;
    double mean_virtual = 0; // mirrors per step (mirror) or wall particles (fixed), all ranks
    double wall_s = 0;
    double interactions_total = 0; // over all steps and ranks
    std::vector<IntervalRecord> intervals;
    PhysicsSeries physics;
    std::vector<double> peak_rss_bytes;                                             // per rank
    std::vector<std::array<double, static_cast<std::size_t>(Phase::count)>> timers; // per rank
    std::vector<double> idle_s;                                                     // per rank
    std::vector<double> initial_columns; // fluid particles per cell column at t = 0
    std::vector<double> wall_columns;    // fixed wall particles per cell column (static)
    std::vector<int> placement_pus;      // first processing unit each rank is bound to, -1: none
    std::vector<std::string> placement_nodes; // node of each rank (SLURMD_NODENAME, else host)
    std::vector<RebalanceRecord> rebalances;  // balanced decomposition only
    std::vector<int> final_cuts;              // the slabs at the end of the run
    // The machine profile's figure for the latency probe (the exchange benchmark's gap-0
    // 64-byte shift at this load); 0 when the run does not probe.
    double profile_probe_shift_s = 0;
    // What comm_predict_s is: "exchange benchmark" (within the cores), "time-shared step
    // replayed" (above them, one-thread ranks on one node, blocking exchanges); empty without
    // --machine.
    std::string comm_predict_source;
    std::int64_t restarted_from_step = -1; // the checkpoint's step, -1: not a restart
    std::filesystem::path restarted_from;  // its directory
};

} // namespace sphperf::sph
