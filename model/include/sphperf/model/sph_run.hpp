#pragma once
// An SPH report read into typed structures (nlohmann from_json): a missing key, a wrong type,
// a non-finite or negative figure is a UsageError naming the file and the key.
#include "sphperf/sph/timers.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace sphperf::model {

// One rank over one report interval; counts are means per step, times totals over the interval.
struct RankStats {
    double steps = 0, field = 0, field_mean = 0, virtual_ = 0, ghost = 0, pairs = 0;
    double interactions = 0, exported = 0, migrated = 0, cell_moves = 0, idle_s = 0;
    double messages = 0, message_bytes = 0, comm_predict_s = 0, comm_hockney_s = 0;
    // comm_predict_s by the exchange benchmark alone (above the cores comm_predict_s is the step
    // replayed since session 40); older reports: their comm_predict_s
    double comm_predict_exchange_s = 0;
    double descents = 0; // neighbours found out of id order per step (the id sort's work)
    // sph --overlap: compute run while ghost transfers were in flight, and the predicted
    // transfer time it hid (inline, sph --machine); 0 in blocking runs.
    double overlap_s = 0, hidden_predict_s = 0;
    double halo_comm_s = 0;   // comm_s of the ghost and density exchanges (0 in older reports)
    double probe_shift_s = 0; // the latency probe at the interval's end (0: none, older reports)
    // The speed gauge (sph/include/sphperf/sph/gauge.hpp): CPU seconds of its samples, total,
    // and how many (0: none, older reports or --speed-gauge-every 0)
    double gauge_cpu_s = 0, gauge_samples = 0;
    // The core latency gauge (gauge.hpp): its readings' round trips between threads 0 and 1,
    // total, and how many (0: one thread, threads taking turns, or an older report)
    double core_round_trip_s = 0, core_round_trip_samples = 0;
    std::map<std::string, double> timers; // "pairs_s", "comm_s", "wait_s", ...
    // comm_s and comm_predict_s by exchange (sph::shift_keys); older reports: zeros
    sph::ShiftTimes shift_comm_s{}, shift_predict_s{};
    // comm_predict_s by the rule before session 32 (model::GapRule::own_kind_gap); reports
    // before it predicted by that rule, so their comm_predict_s stands in
    sph::ShiftTimes shift_predict_own_kind_s{};
    // CPU time before each blocking shift (sph cpu_before_s, session 40); older reports: absent
    sph::ShiftTimes segment_cpu_s{};
    bool has_segment_cpu = false;

    double timer(const std::string &key) const;
    // Everything the rank computes locally per step (all phases but comm, wait and output).
    double compute_s() const;
    // Every time this rank-interval measured, times `factor` (SphRun::scale_times).
    void scale_times(double factor);
};

struct IntervalStats {
    std::int64_t step = 0;
    double time_s = 0;
    std::vector<double> columns; // fluid particles per cell column at the interval's end
    std::vector<RankStats> ranks;
    // Stored-list grids: interactions and descents per cell column, means per step over the
    // interval, all ranks (empty: Cell+Sorted, or a report before session 56).
    std::vector<double> column_interactions, column_descents;
};

struct RunConfig {
    std::string setup, grid, boundary;
    double scale = 1, delta = 0.01, dt = 1e-4, cell_size = 0, tank_length = 0;
    std::int64_t steps = 0, fluid_particles = 0;
    int ranks = 1, threads = 1, interval = 1, cell_columns = 0;
    int nodes = 1; // distinct nodes the ranks ran on (reports before multi-node runs: 1)
    std::string decomposition = "equal"; // reports before balanced slabs: equal
    double rebalance_s = 0;              // balanced: the re-cuts' time, slowest rank, summed
    bool overlap = false;                // sph --overlap: non-blocking ghost exchanges
};

struct SphRun {
    std::string path, host, git_commit;
    RunConfig config;
    double wall_s = 0, record_bytes = 0;
    std::vector<IntervalStats> intervals;
    std::vector<double> initial_columns, wall_columns, peak_rss_bytes;
    std::vector<int> placement_pus;
    // The machine profile's figure for the latency probe (0: the run did not probe).
    double profile_probe_shift_s = 0;

    // The speed gauge's CPU seconds per sample over the whole run: each rank-interval's mean
    // weighted by its compute (0: no samples).
    double gauge_per_sample_s() const;
    // The same over one rank's rank-intervals: the speed of the core that rank ran on (0: no
    // samples, or no such rank).
    double rank_gauge_per_sample_s(std::size_t rank) const;
    // The core latency gauge over the whole run: the mean round trip of its samples and the
    // share of them in rank-intervals whose mean is above `far_s` (the far mode); nullopt
    // where the run has no sample.
    struct CoreLatency {
        double round_trip_s = 0, far_fraction = 0, samples = 0;
    };
    std::optional<CoreLatency> core_latency(double far_s) const;
    // This VM's two vCPUs pass a line in about 60 ns in most spells, about 350 ns in the far
    // ones (sph/NOTES.md, session 70): a rank-interval whose mean is above this is far.
    static constexpr double far_core_round_trip_s = 150e-9;
    // core_latency as JSON {round_trip_s, far_fraction, samples, far_above_s}, null: none.
    nlohmann::json core_latency_json() const;
    // The same per interval, pooled over the intervals within `half_window` of it (each
    // rank-interval weighted by its compute; by its samples where no rank computed; the whole
    // run's figure where the window has no sample): the host's speed as the run went. Pooled
    // as the weighted median of the rank-intervals' means (a gauge sample is 30 us of
    // arithmetic: one hit by a host interrupt reads 1.5-4 times the others while the interval's
    // compute does not move, session 54), or as their weighted mean (sessions 51-53).
    enum class Pooling { median, mean };
    std::vector<double> interval_gauges_s(int half_window, Pooling pooling = Pooling::median) const;
    // Every time the run measured (wall, timers, idle, transfers, CPU segments), times
    // `factor`: the run as it would have measured on a host `factor` times slower. Predictions
    // the run recorded (comm_predict_s ...) and the latency probe are left as they are.
    void scale_times(double factor);
    // The same with one factor per interval (`factors` has one entry per interval): the
    // interval's rank times by its own; the wall and the re-cuts by the mean factor, each
    // interval weighted by its ranks' compute (the wall as the sum of its intervals).
    void scale_times(std::span<const double> factors);
};

SphRun load_sph_run(const std::filesystem::path &path);

} // namespace sphperf::model
