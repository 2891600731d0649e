#include "sphperf/model/sph_run.hpp"

#include "sphperf/errors.hpp"
#include "sphperf/model/profile.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>

namespace sphperf::model {

namespace {
using nlohmann::json;

// Non-finite or negative counts and times are as wrong as missing ones.
void check_figure(double v, const std::string &key) {
    if (!std::isfinite(v) || v < 0)
        throw json::other_error::create(
            501, "key '" + key + "' holds " + std::to_string(v) + ", expected a finite value >= 0",
            nullptr);
}
double figure(const json &j, const char *key) {
    const double v = j.at(key).get<double>();
    check_figure(v, key);
    return v;
}
} // namespace

void from_json(const json &j, RankStats &r) {
    r.steps = figure(j, "steps");
    r.field = figure(j, "field");
    r.field_mean = figure(j, "field_mean");
    r.virtual_ = figure(j, "virtual");
    r.ghost = figure(j, "ghost");
    r.pairs = figure(j, "pairs");
    r.interactions = figure(j, "interactions");
    r.exported = figure(j, "exported");
    r.migrated = figure(j, "migrated");
    r.cell_moves = figure(j, "cell_moves");
    r.idle_s = figure(j, "idle_s");
    r.messages = figure(j, "messages");
    r.message_bytes = figure(j, "message_bytes");
    r.comm_predict_s = figure(j, "comm_predict_s");
    r.comm_predict_exchange_s = j.contains("comm_predict_exchange_s")
                                    ? figure(j, "comm_predict_exchange_s")
                                    : r.comm_predict_s;
    // Reports before the exchange benchmark predicted by Hockney alone.
    r.comm_hockney_s =
        j.contains("comm_hockney_s") ? figure(j, "comm_hockney_s") : r.comm_predict_s;
    // Reports before the memory-order count: 0, as for the sorted grid (the term then drops).
    r.descents = j.contains("descents") ? figure(j, "descents") : 0.0;
    r.overlap_s = j.contains("overlap_s") ? figure(j, "overlap_s") : 0.0;
    r.halo_comm_s = j.contains("halo_comm_s") ? figure(j, "halo_comm_s") : 0.0;
    r.probe_shift_s = j.contains("probe_shift_s") ? figure(j, "probe_shift_s") : 0.0;
    r.gauge_cpu_s = j.contains("gauge_cpu_s") ? figure(j, "gauge_cpu_s") : 0.0;
    r.gauge_samples = j.contains("gauge_samples") ? figure(j, "gauge_samples") : 0.0;
    r.core_round_trip_s = j.contains("core_round_trip_s") ? figure(j, "core_round_trip_s") : 0.0;
    r.core_round_trip_samples =
        j.contains("core_round_trip_samples") ? figure(j, "core_round_trip_samples") : 0.0;
    r.hidden_predict_s =
        j.contains("comm_hidden_predict_s") ? figure(j, "comm_hidden_predict_s") : 0.0;
    if (j.contains("shifts"))
        for (std::size_t k = 0; k < sph::shift_keys.size(); ++k) {
            const std::string key(sph::shift_keys[k]);
            const auto &s = j.at("shifts").at(key);
            r.shift_comm_s[k] = figure(s, "comm_s");
            r.shift_predict_s[k] = figure(s, "comm_predict_s");
            r.shift_predict_own_kind_s[k] = s.contains("comm_predict_own_kind_gap_s")
                                                ? figure(s, "comm_predict_own_kind_gap_s")
                                                : r.shift_predict_s[k];
            if (s.contains("cpu_before_s")) {
                r.segment_cpu_s[k] = figure(s, "cpu_before_s");
                r.has_segment_cpu = true;
            }
        }
    for (const auto &[k, v] : j.at("timers").items()) {
        r.timers[k] = v.get<double>();
        check_figure(r.timers[k], "timers/" + k);
    }
    for (const char *k : {"pairs_s", "grid_s", "comp_s", "comm_s", "wait_s", "pack_s"})
        if (!r.timers.count(k))
            throw json::out_of_range::create(403, std::string("key 'timers/") + k + "' not found",
                                             nullptr);
}

void from_json(const json &j, IntervalStats &iv) {
    iv.step = j.at("step").get<std::int64_t>();
    iv.time_s = figure(j, "time_s");
    iv.columns = j.at("columns").get<std::vector<double>>();
    iv.ranks = j.at("ranks").get<std::vector<RankStats>>();
    // Stored-list grids since session 56: interactions and descents per column.
    if (j.contains("column_interactions")) {
        iv.column_interactions = j.at("column_interactions").get<std::vector<double>>();
        iv.column_descents = j.at("column_descents").get<std::vector<double>>();
    }
}

void from_json(const json &j, RunConfig &c) {
    c.setup = j.at("setup").get<std::string>();
    c.grid = j.at("grid").get<std::string>();
    c.boundary = j.at("boundary").get<std::string>();
    c.scale = figure(j, "scale");
    c.delta = figure(j, "delta");
    c.dt = figure(j, "dt");
    c.cell_size = figure(j, "cell_size");
    c.tank_length = figure(j, "tank_length");
    c.steps = j.at("steps").get<std::int64_t>();
    c.fluid_particles = j.at("fluid_particles").get<std::int64_t>();
    c.ranks = j.at("ranks").get<int>();
    c.threads = j.at("threads").get<int>();
    c.interval = j.at("interval").get<int>();
    c.cell_columns = j.at("cell_columns").get<int>();
    c.overlap = j.value("overlap", false); // reports before sph --overlap: blocking
    if (c.ranks < 1 || c.threads < 1 || c.cell_columns < 1 || c.steps < 0)
        throw json::other_error::create(501, "config holds a non-positive count", nullptr);
}

double RankStats::timer(const std::string &key) const {
    const auto it = timers.find(key);
    return it == timers.end() ? 0.0 : it->second;
}

double RankStats::compute_s() const {
    double s = 0;
    for (const auto &[k, v] : timers)
        if (k != "comm_s" && k != "wait_s" && k != "output_s" && k != "rebalance_s")
            s += v;
    return s;
}

namespace {
// The gauge samples of some rank-intervals: their mean per sample weighted by each
// rank-interval's compute (the factor scales compute), or, where none computed, the plain mean;
// and the (per sample, compute) pairs for a weighted median.
struct GaugePool {
    double weighted = 0, weight = 0, cpu = 0, samples = 0;
    std::vector<std::pair<double, double>> values;
    void add(const RankStats &r) {
        if (r.gauge_samples <= 0)
            return;
        const double per_sample = r.gauge_cpu_s / r.gauge_samples, compute = r.compute_s();
        weighted += compute * per_sample;
        weight += compute;
        cpu += r.gauge_cpu_s;
        samples += r.gauge_samples;
        if (compute > 0)
            values.emplace_back(per_sample, compute);
    }
    bool weighted_by_compute() const { return weight > 0; }
    // `none`: the value where no rank-interval has a sample.
    double mean(double none) const {
        return weight > 0 ? weighted / weight : samples > 0 ? cpu / samples : none;
    }
};
} // namespace

double SphRun::gauge_per_sample_s() const {
    // Weighted by each rank-interval's compute: the factor scales compute, and a rank without
    // field particles (a dam break's far slab, waiting in MPI) reads its own core's speed,
    // 10-70 % off its busy neighbour's (session 50), at no cost to the run.
    GaugePool pool;
    for (const auto &iv : intervals)
        for (const auto &r : iv.ranks)
            pool.add(r);
    return pool.mean(0.0);
}

double SphRun::rank_gauge_per_sample_s(std::size_t rank) const {
    GaugePool pool;
    for (const auto &iv : intervals)
        if (rank < iv.ranks.size())
            pool.add(iv.ranks[rank]);
    return pool.mean(0.0);
}

std::optional<SphRun::CoreLatency> SphRun::core_latency(double far_s) const {
    CoreLatency c;
    double total = 0, far = 0;
    for (const auto &iv : intervals)
        for (const auto &r : iv.ranks)
            if (r.core_round_trip_samples > 0) {
                total += r.core_round_trip_s;
                c.samples += r.core_round_trip_samples;
                if (r.core_round_trip_s / r.core_round_trip_samples > far_s)
                    far += r.core_round_trip_samples;
            }
    if (!(c.samples > 0))
        return std::nullopt;
    c.round_trip_s = total / c.samples;
    c.far_fraction = far / c.samples;
    return c;
}

nlohmann::json SphRun::core_latency_json() const {
    const auto c = core_latency(far_core_round_trip_s);
    if (!c)
        return nullptr;
    return {{"round_trip_s", c->round_trip_s},
            {"far_fraction", c->far_fraction},
            {"samples", c->samples},
            {"far_above_s", far_core_round_trip_s}};
}

namespace {
// The weighted median of (value, weight) pairs with positive weights: the value where the
// cumulative weight reaches half the total (the mean of two values where it lands exactly on
// the boundary between them).
double weighted_median(std::vector<std::pair<double, double>> v) {
    std::sort(v.begin(), v.end());
    double total = 0;
    for (const auto &[x, w] : v)
        total += w;
    double cumulative = 0;
    for (std::size_t i = 0; i < v.size(); ++i) {
        cumulative += v[i].second;
        if (cumulative > 0.5 * total * (1 + 1e-12))
            return v[i].first;
        if (cumulative >= 0.5 * total * (1 - 1e-12))
            return i + 1 < v.size() ? 0.5 * (v[i].first + v[i + 1].first) : v[i].first;
    }
    return v.back().first;
}
} // namespace

std::vector<double> SphRun::interval_gauges_s(int half_window, Pooling pooling) const {
    const double whole = gauge_per_sample_s();
    const auto n = static_cast<long>(intervals.size());
    std::vector<double> out;
    for (long k = 0; k < n; ++k) {
        GaugePool pool;
        for (long i = std::max(0L, k - half_window); i <= std::min(n - 1, k + half_window); ++i)
            for (const auto &r : intervals[static_cast<std::size_t>(i)].ranks)
                pool.add(r);
        out.push_back(pool.weighted_by_compute() && pooling == Pooling::median
                          ? weighted_median(std::move(pool.values))
                          : pool.mean(whole));
    }
    return out;
}

void SphRun::scale_times(std::span<const double> factors) {
    if (factors.size() != intervals.size())
        throw std::invalid_argument("SphRun::scale_times: one factor per interval expected");
    double weighted = 0, weight = 0;
    for (std::size_t k = 0; k < intervals.size(); ++k)
        for (const auto &r : intervals[k].ranks) {
            weighted += r.compute_s() * factors[k];
            weight += r.compute_s();
        }
    double mean = 0;
    for (double f : factors)
        mean += f / static_cast<double>(factors.size());
    const double whole = weight > 0 ? weighted / weight : mean;
    wall_s *= whole;
    config.rebalance_s *= whole;
    for (std::size_t k = 0; k < intervals.size(); ++k)
        for (auto &r : intervals[k].ranks)
            r.scale_times(factors[k]);
}

void RankStats::scale_times(double factor) {
    for (auto &[k, v] : timers)
        v *= factor;
    idle_s *= factor;
    overlap_s *= factor;
    halo_comm_s *= factor;
    gauge_cpu_s *= factor;
    for (auto *a : {&shift_comm_s, &segment_cpu_s})
        for (double &v : *a)
            v *= factor;
}

void SphRun::scale_times(double factor) {
    wall_s *= factor;
    config.rebalance_s *= factor;
    for (auto &iv : intervals)
        for (auto &r : iv.ranks)
            r.scale_times(factor);
}

SphRun load_sph_run(const std::filesystem::path &path) {
    const json j = load_report(path, "sph");
    SphRun r;
    r.path = path.string();
    try {
        r.host = j.at("host").get<std::string>();
        r.git_commit = j.value("git_commit", "");
        r.config = j.at("config").get<RunConfig>();
        r.wall_s = figure(j, "wall_s");
        r.record_bytes = figure(j, "record_bytes");
        r.intervals = j.at("intervals").get<std::vector<IntervalStats>>();
        r.initial_columns = j.at("initial_columns").get<std::vector<double>>();
        r.wall_columns = j.at("wall_columns").get<std::vector<double>>();
        r.peak_rss_bytes = j.at("peak_rss_bytes").get<std::vector<double>>();
        r.placement_pus = j.at("placement_pus").get<std::vector<int>>();
        r.profile_probe_shift_s =
            j.contains("profile_probe_shift_s") ? figure(j, "profile_probe_shift_s") : 0.0;
        // Reports before multi-node runs were on one node.
        r.config.nodes = j.value("nodes", 1);
        if (j.contains("decomposition")) {
            const auto &d = j.at("decomposition");
            r.config.decomposition = d.at("kind").get<std::string>();
            for (const auto &b : d.at("rebalances"))
                r.config.rebalance_s += figure(b, "rebalance_s");
        }
    } catch (const json::exception &e) {
        throw UsageError("'" + path.string() + "': " + e.what());
    }
    const auto cols = static_cast<std::size_t>(r.config.cell_columns);
    auto bad = [&](const std::string &what) {
        throw UsageError("'" + path.string() + "': " + what);
    };
    if (j.contains("restart"))
        bad("continues a checkpoint (sph --restart, from step " +
            j["restart"].value("from_step", json(-1)).dump() +
            "): its wall_s times only the steps after it; use uninterrupted runs");
    // The model costs the ghost and density exchanges as MPI messages (Hockney, exchange
    // benchmark); a run that sent them through a shared window measured something else.
    if (const auto t = j.at("config").value("halo_transport", std::string("messages"));
        t != "messages")
        bad("ran with sph --halo-transport " + t +
            ", which the model does not cost (it costs MPI messages): expected runs with "
            "--halo-transport messages");
    if (r.intervals.empty())
        bad("no intervals recorded (a run of 0 steps cannot calibrate anything)");
    if (r.initial_columns.size() != cols || r.wall_columns.size() != cols)
        bad("column histograms do not have config/cell_columns = " + std::to_string(cols) +
            " entries");
    if (r.config.nodes < 1 || r.config.nodes > r.config.ranks)
        bad("nodes " + std::to_string(r.config.nodes) +
            " is outside 1..config/ranks = " + std::to_string(r.config.ranks));
    if (r.placement_pus.size() != static_cast<std::size_t>(r.config.ranks))
        bad("placement_pus has " + std::to_string(r.placement_pus.size()) +
            " entries, expected config/ranks = " + std::to_string(r.config.ranks));
    for (const auto &iv : r.intervals) {
        if (iv.columns.size() != cols)
            bad("interval at step " + std::to_string(iv.step) + " has " +
                std::to_string(iv.columns.size()) + " columns, expected " + std::to_string(cols));
        if (!iv.column_interactions.empty() &&
            (iv.column_interactions.size() != cols || iv.column_descents.size() != cols))
            bad("interval at step " + std::to_string(iv.step) +
                " has column_interactions or column_descents not of config/cell_columns = " +
                std::to_string(cols) + " entries");
        if (iv.ranks.size() != static_cast<std::size_t>(r.config.ranks))
            bad("interval at step " + std::to_string(iv.step) + " has " +
                std::to_string(iv.ranks.size()) +
                " ranks, expected config/ranks = " + std::to_string(r.config.ranks));
    }
    return r;
}

} // namespace sphperf::model
