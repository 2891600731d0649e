#include "sphperf/model/workload.hpp"

#include "sphperf/errors.hpp"
#include "sphperf/model/fit.hpp"
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/domain.hpp"
#include "sphperf/sph/setup.hpp"
#include "sphperf/stats.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>
#include <sstream>

namespace sphperf::model {

nlohmann::json Trace::to_json() const {
    return {{"setup", setup},
            {"source", source},
            {"scale", scale},
            {"delta", delta},
            {"cell_size", cell_size},
            {"tank_length", tank_length},
            {"times_s", times_s},
            {"columns", columns},
            {"pairs_per_field", pairs_per_field},
            {"interactions_per_field", interactions_per_field}};
}

Trace Trace::from_json(const nlohmann::json &j, const std::string &where) {
    Trace t;
    try {
        t.setup = j.at("setup").get<std::string>();
        t.source = j.value("source", "");
        t.scale = j.at("scale").get<double>();
        t.delta = j.at("delta").get<double>();
        t.cell_size = j.at("cell_size").get<double>();
        t.tank_length = j.at("tank_length").get<double>();
        t.times_s = j.at("times_s").get<std::vector<double>>();
        t.columns = j.at("columns").get<std::vector<std::vector<double>>>();
        t.pairs_per_field = j.at("pairs_per_field").get<std::vector<double>>();
        t.interactions_per_field = j.at("interactions_per_field").get<std::vector<double>>();
    } catch (const nlohmann::json::exception &e) {
        throw UsageError(where + ": " + e.what());
    }
    if (t.times_s.empty() || t.times_s.size() != t.columns.size() ||
        t.times_s.size() != t.pairs_per_field.size() ||
        t.times_s.size() != t.interactions_per_field.size() || !(t.cell_size > 0) ||
        !(t.tank_length > 0))
        throw UsageError(where + ": a trace needs as many histograms, pairs_per_field and "
                                 "interactions_per_field as times, and positive cell_size and "
                                 "tank_length");
    return t;
}

Trace trace_of(const SphRun &run) {
    Trace t;
    t.setup = run.config.setup;
    t.source = run.path;
    t.scale = run.config.scale;
    t.delta = run.config.delta;
    t.cell_size = run.config.cell_size;
    t.tank_length = run.config.tank_length;
    t.times_s.push_back(0.0);
    t.columns.push_back(run.initial_columns);
    for (const auto &iv : run.intervals) {
        t.times_s.push_back(iv.time_s);
        t.columns.push_back(iv.columns);
        double field = 0, pairs = 0, interactions = 0;
        for (const auto &rk : iv.ranks) {
            field += rk.field_mean;
            pairs += rk.pairs;
            interactions += rk.interactions;
        }
        t.pairs_per_field.push_back(field > 0 ? pairs / field : 0.0);
        t.interactions_per_field.push_back(field > 0 ? interactions / field : 0.0);
    }
    // t = 0 takes the first interval's density (the lattice barely moves in one interval).
    if (!run.intervals.empty()) {
        t.pairs_per_field.insert(t.pairs_per_field.begin(), t.pairs_per_field.front());
        t.interactions_per_field.insert(t.interactions_per_field.begin(),
                                        t.interactions_per_field.front());
    } else {
        t.pairs_per_field.push_back(0.0);
        t.interactions_per_field.push_back(0.0);
    }
    return t;
}

namespace {
std::vector<double> histogram(const std::vector<sph::ParticleRecord> &particles, double cell,
                              int columns) {
    std::vector<double> h(static_cast<std::size_t>(columns), 0.0);
    for (const auto &r : particles)
        h[static_cast<std::size_t>(
            std::clamp(static_cast<int>(std::floor(r.x / cell)), 0, columns - 1))] += 1;
    return h;
}
std::string num(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}
} // namespace

Target make_target(const std::string &setup, const std::string &grid, double scale, double delta,
                   double dt, int ranks, int threads) {
    sph::Config cfg;
    cfg.setup = sph::parse_setup(setup);
    cfg.grid = sph::parse_grid(grid);
    cfg.scale = scale;
    cfg.dt = dt;
    cfg.steps = 1;
    cfg.physics.delta = delta;
    cfg.physics.h = sph::Physics::h_factor * delta * std::sqrt(2.0);
    const sph::Geometry geo = sph::make_geometry(cfg);
    sph::validate(cfg, geo, ranks); // the app's own checks: CFL, ranks <= columns, ...
    Target t;
    t.setup = setup;
    t.grid = grid;
    t.scale = scale;
    t.delta = delta;
    t.dt = dt;
    t.ranks = ranks;
    t.threads = threads;
    t.cell_size = geo.cell_size;
    t.tank_length = geo.tank_length;
    t.columns = geo.cell_columns;
    const auto fluid = sph::make_fluid(geo, cfg.physics);
    t.fluid_particles = static_cast<double>(fluid.size());
    t.initial_columns = histogram(fluid, geo.cell_size, geo.cell_columns);
    t.wall_columns =
        histogram(sph::make_walls(geo, cfg.physics, static_cast<std::int64_t>(fluid.size())),
                  geo.cell_size, geo.cell_columns);
    return t;
}

double source_time(double target_time, double source_scale, double target_scale) {
    return target_time * std::sqrt(source_scale / target_scale);
}

std::vector<double> rescale_columns(const std::vector<double> &source, double source_cell,
                                    double source_tank, double target_cell, double target_tank,
                                    int target_columns, double target_total) {
    const double stretch = target_tank / source_tank; // target length per source length
    std::vector<double> out(static_cast<std::size_t>(target_columns), 0.0);
    const auto ns = static_cast<int>(source.size());
    for (int c = 0; c < target_columns; ++c) {
        // The last column reaches the tank wall (it may be a partial cell).
        const double a = c * target_cell / stretch;
        const double b =
            (c + 1 == target_columns) ? source_tank + source_cell : (c + 1) * target_cell / stretch;
        double sum = 0;
        for (int s = std::max(0, static_cast<int>(a / source_cell) - 1);
             s < ns && s * source_cell < b; ++s) {
            const double lo = s * source_cell;
            // The source's last column also holds what lies beyond the tank end.
            const double hi =
                (s + 1 == ns) ? std::max(source_tank, lo + source_cell) : lo + source_cell;
            const double overlap = std::min(b, hi) - std::max(a, lo);
            if (overlap > 0)
                sum += source[static_cast<std::size_t>(s)] * overlap / (hi - lo);
        }
        out[static_cast<std::size_t>(c)] = sum;
    }
    const double total = std::accumulate(out.begin(), out.end(), 0.0);
    if (total > 0)
        for (auto &v : out)
            v *= target_total / total;
    return out;
}

namespace {
// Where t falls among increasing record times: records lo and hi and the weight of hi (lo == hi
// before the first record and after the last).
struct Bracket {
    std::size_t lo = 0, hi = 0;
    double w = 0;
};
Bracket bracket(const std::vector<double> &times, double t) {
    const auto k =
        static_cast<std::size_t>(std::lower_bound(times.begin(), times.end(), t) - times.begin());
    if (k == 0)
        return {0, 0, 0.0};
    if (k >= times.size())
        return {times.size() - 1, times.size() - 1, 0.0};
    const double t0 = times[k - 1], t1 = times[k];
    return {k - 1, k, t1 > t0 ? (t - t0) / (t1 - t0) : 1.0};
}

void require_reach(const Trace &trace, double t) {
    constexpr double tolerance = 1e-9;
    if (t > trace.end_time() + tolerance)
        throw UsageError("the prediction needs the " + trace.setup + " trace up to " + num(t) +
                         " s of simulated time at scale " + num(trace.scale) +
                         ", but the calibration recorded only " + num(trace.end_time()) +
                         " s: calibrate with a run reaching --end-time " + num(t));
}
} // namespace

std::vector<double> histogram_at(const Trace &trace, double t) {
    require_reach(trace, t);
    const auto [lo, hi, w] = bracket(trace.times_s, t);
    std::vector<double> h(trace.columns[hi].size());
    for (std::size_t c = 0; c < h.size(); ++c)
        h[c] = (1 - w) * trace.columns[lo][c] + w * trace.columns[hi][c];
    return h;
}

WorkDensity density_at(const Trace &trace, double t) {
    require_reach(trace, t);
    const auto [lo, hi, w] = bracket(trace.times_s, t);
    return {(1 - w) * trace.pairs_per_field[lo] + w * trace.pairs_per_field[hi],
            (1 - w) * trace.interactions_per_field[lo] + w * trace.interactions_per_field[hi]};
}

IdleOnset idle_onset(const Trace &trace, const Target &target, const std::vector<int> &cuts,
                     double dt, std::int64_t steps) {
    IdleOnset o;
    o.per_rank.assign(cuts.size() - 1, std::nullopt);
    const std::int64_t stride = std::max<std::int64_t>(1, steps / 20000);
    for (std::int64_t s = 0; s <= steps; s += stride) {
        const double t = static_cast<double>(s) * dt;
        const auto cols =
            rescale_columns(histogram_at(trace, source_time(t, trace.scale, target.scale)),
                            trace.cell_size, trace.tank_length, target.cell_size,
                            target.tank_length, target.columns, target.fluid_particles);
        const auto slabs = recut(cols, target.wall_columns, cuts);
        bool all = true;
        for (std::size_t r = 0; r < slabs.size(); ++r) {
            if (!o.per_rank[r] && slabs[r].field >= 1)
                o.per_rank[r] = s;
            all = all && o.per_rank[r].has_value();
        }
        if (all) {
            o.all = s;
            break;
        }
    }
    return o;
}

std::vector<SlabLoad> recut(const std::vector<double> &fluid, const std::vector<double> &walls,
                            int ranks) {
    const int columns = static_cast<int>(fluid.size());
    if (ranks > columns)
        throw UsageError(std::to_string(ranks) + " ranks exceed the " + std::to_string(columns) +
                         " cell columns of the tank: each rank needs at least one column");
    return recut(fluid, walls, sph::equal_cuts(ranks, columns));
}

std::vector<SlabLoad> recut(const std::vector<double> &fluid, const std::vector<double> &walls,
                            const std::vector<int> &cuts) {
    const int columns = static_cast<int>(fluid.size());
    const int ranks = static_cast<int>(cuts.size()) - 1;
    sph::check_cuts(cuts, ranks, columns);
    std::vector<SlabLoad> out(static_cast<std::size_t>(ranks));
    auto at = [&](const std::vector<double> &v, int c) { return v[static_cast<std::size_t>(c)]; };
    for (int r = 0; r < ranks; ++r) {
        SlabLoad &s = out[static_cast<std::size_t>(r)];
        s.begin = cuts[static_cast<std::size_t>(r)];
        s.end = cuts[static_cast<std::size_t>(r) + 1];
        for (int c = s.begin; c < s.end; ++c) {
            s.field += at(fluid, c);
            s.walls += at(walls, c);
        }
        // The app sends every particle of an edge column facing a neighbour (a one-column
        // slab sends its column both ways).
        if (r > 0)
            s.export_west = at(fluid, s.begin) + at(walls, s.begin);
        if (r + 1 < ranks)
            s.export_east = at(fluid, s.end - 1) + at(walls, s.end - 1);
        s.exported = s.export_west + s.export_east;
    }
    for (int r = 0; r < ranks; ++r) {
        SlabLoad &s = out[static_cast<std::size_t>(r)];
        if (r > 0)
            s.ghost += out[static_cast<std::size_t>(r - 1)].export_east;
        if (r + 1 < ranks)
            s.ghost += out[static_cast<std::size_t>(r + 1)].export_west;
    }
    return out;
}

} // namespace sphperf::model

namespace sphperf::model {

double Disorder::at(double time_s, double target_delta) const {
    // Acoustic time (spacing / sound speed, the sound speed fixed by the setup) maps a run at
    // another spacing onto the measured one.
    const double t = time_s * delta / target_delta;
    if (times_s.empty())
        return 0.0;
    if (t > times_s.back() * (1 + 1e-9))
        throw UsageError("the model's memory-order record (" + source + ") ends at " +
                         num(times_s.back()) + " s of simulated time, this prediction needs " +
                         num(t) + " s: calibrate with a list or table run that long");
    const auto [lo, hi, w] = bracket(times_s, t);
    return (1 - w) * per_interaction[lo] + w * per_interaction[hi];
}

nlohmann::json Disorder::to_json() const {
    return {{"source", source},
            {"delta", delta},
            {"times_s", times_s},
            {"descents_per_interaction", per_interaction}};
}

Disorder Disorder::from_json(const nlohmann::json &j, const std::string &where) {
    Disorder d;
    try {
        d.source = j.value("source", "");
        d.delta = j.at("delta").get<double>();
        d.times_s = j.at("times_s").get<std::vector<double>>();
        d.per_interaction = j.at("descents_per_interaction").get<std::vector<double>>();
    } catch (const nlohmann::json::exception &e) {
        throw UsageError(where + ": " + e.what());
    }
    if (d.times_s.size() != d.per_interaction.size() || !(d.delta > 0) ||
        !std::is_sorted(d.times_s.begin(), d.times_s.end()))
        throw UsageError(where + ": needs as many values as increasing times and delta > 0");
    return d;
}

Disorder disorder_of(const std::vector<SphRun> &runs) {
    Disorder d;
    if (runs.empty())
        return d;
    const SphRun &first = runs.front();
    d.delta = first.config.delta;
    for (const auto &iv : first.intervals)
        d.times_s.push_back(iv.time_s);
    d.per_interaction.assign(d.times_s.size(), 0.0);
    for (const auto &r : runs) {
        if (r.intervals.size() != d.times_s.size())
            throw std::invalid_argument("disorder_of: runs with different record times");
        d.source += (d.source.empty() ? "" : ", ") + r.path;
        for (std::size_t k = 0; k < r.intervals.size(); ++k) {
            double desc = 0, inter = 0;
            for (const auto &rk : r.intervals[k].ranks) {
                desc += rk.descents;
                inter += rk.interactions;
            }
            d.per_interaction[k] += (inter > 0 ? desc / inter : 0.0) / double(runs.size());
        }
    }
    return d;
}

} // namespace sphperf::model

namespace sphperf::model {

ColumnDisorder::SlabOrder ColumnDisorder::slab_order(double target_time_s, double target_scale,
                                                     double target_cell, double target_tank,
                                                     int target_columns,
                                                     const std::vector<int> &cuts) const {
    const double ts = source_time(target_time_s, scale, target_scale);
    if (times_s.empty() || ts > times_s.back() * (1 + 1e-9))
        throw UsageError("the model's per-column memory order (" + source + ") ends at " +
                         num(end_time()) + " s of simulated time at scale " + num(scale) +
                         ", this prediction needs " + num(ts) +
                         " s: calibrate with a list or table run that long, or predict with "
                         "--rank-disorder none");
    const auto [lo, hi, w] = bracket(times_s, ts);
    auto at = [&, lo = lo, hi = hi, w = w](const std::vector<std::vector<double>> &v) {
        std::vector<double> out(v[lo].size());
        for (std::size_t k = 0; k < out.size(); ++k)
            out[k] = (1 - w) * v[lo][k] + w * v[hi][k];
        return out;
    };
    const auto src_i = at(interactions), src_d = at(descents);
    const double total_i = std::accumulate(src_i.begin(), src_i.end(), 0.0);
    const double total_d = std::accumulate(src_d.begin(), src_d.end(), 0.0);
    // Both carried by the same rule, so a column's descents per interaction keep.
    const auto inter = rescale_columns(src_i, cell_size, tank_length, target_cell, target_tank,
                                       target_columns, total_i);
    const auto desc = rescale_columns(src_d, cell_size, tank_length, target_cell, target_tank,
                                      target_columns, total_d);
    SlabOrder out;
    out.all = total_i > 0 ? total_d / total_i : 0.0;
    for (std::size_t r = 0; r + 1 < cuts.size(); ++r) {
        double i = 0, d = 0;
        for (int c = cuts[r]; c < cuts[r + 1]; ++c) {
            i += inter[static_cast<std::size_t>(c)];
            d += desc[static_cast<std::size_t>(c)];
        }
        out.slabs.push_back(i > 0 ? std::optional<double>(d / i) : std::nullopt);
    }
    return out;
}

ColumnDisorder::SlabOrder ColumnDisorder::at_whole_order(SlabOrder order, double whole) {
    if (!(order.all > 0))
        return order;
    const double ratio = whole / order.all;
    for (auto &d : order.slabs)
        if (d)
            *d *= ratio;
    return order;
}

std::vector<double> ColumnDisorder::factors(const SlabOrder &order) const {
    const double base = intercept_s + slope_s * order.all;
    std::vector<double> out;
    for (const auto &d : order.slabs) {
        const double own = d ? intercept_s + slope_s * *d : 0.0;
        out.push_back(d && base > 0 && own > 0 ? own / base : 1.0);
    }
    return out;
}

std::vector<double> ColumnDisorder::rank_factors(double target_time_s, double target_scale,
                                                 double target_cell, double target_tank,
                                                 int target_columns,
                                                 const std::vector<int> &cuts) const {
    return factors(
        slab_order(target_time_s, target_scale, target_cell, target_tank, target_columns, cuts));
}

std::string ColumnDisorder::unusable() const {
    if (!(intercept_s > 0))
        return "the cost line's intercept " + num(intercept_s) + " s is not positive";
    if (!(slope_s > 2 * slope_se_s))
        return "the cost line's slope " + num(slope_s) + " s is not above two standard errors (" +
               num(slope_se_s) + " s)";
    return "";
}

nlohmann::json ColumnDisorder::to_json() const {
    nlohmann::json j{{"source", source},
                     {"scale", scale},
                     {"cell_size", cell_size},
                     {"tank_length", tank_length},
                     {"times_s", times_s},
                     {"column_interactions", interactions},
                     {"column_descents", descents},
                     {"cost_per_interaction",
                      {{"intercept_s", intercept_s},
                       {"intercept_se_s", intercept_se_s},
                       {"slope_s_per_descent_per_interaction", slope_s},
                       {"slope_se_s_per_descent_per_interaction", slope_se_s},
                       {"r2", r2},
                       {"points", points}}}};
    if (!order_source.empty())
        j["descents_from"] = order_source;
    if (!gauge_note.empty())
        j["gauge"] = gauge_note;
    return j;
}

ColumnDisorder ColumnDisorder::from_json(const nlohmann::json &j, const std::string &where) {
    ColumnDisorder d;
    try {
        d.source = j.value("source", "");
        d.order_source = j.value("descents_from", "");
        d.gauge_note = j.value("gauge", "");
        d.scale = j.at("scale").get<double>();
        d.cell_size = j.at("cell_size").get<double>();
        d.tank_length = j.at("tank_length").get<double>();
        d.times_s = j.at("times_s").get<std::vector<double>>();
        d.interactions = j.at("column_interactions").get<std::vector<std::vector<double>>>();
        d.descents = j.at("column_descents").get<std::vector<std::vector<double>>>();
        const auto &c = j.at("cost_per_interaction");
        d.intercept_s = c.at("intercept_s").get<double>();
        d.slope_s = c.at("slope_s_per_descent_per_interaction").get<double>();
        d.intercept_se_s = c.value("intercept_se_s", 0.0);
        d.slope_se_s = c.value("slope_se_s_per_descent_per_interaction", 0.0);
        d.r2 = c.value("r2", 0.0);
        d.points = c.value("points", std::size_t{0});
    } catch (const nlohmann::json::exception &e) {
        throw UsageError(where + ": " + e.what());
    }
    bool ok = !d.times_s.empty() && d.times_s.size() == d.interactions.size() &&
              d.times_s.size() == d.descents.size() && d.scale > 0 && d.cell_size > 0 &&
              d.tank_length > 0 && std::is_sorted(d.times_s.begin(), d.times_s.end());
    for (std::size_t k = 0; ok && k < d.times_s.size(); ++k)
        ok = !d.interactions[k].empty() && d.interactions[k].size() == d.descents[k].size() &&
             d.interactions[k].size() == d.interactions[0].size();
    if (!ok)
        throw UsageError(where + ": needs increasing times, one column_interactions and one "
                                 "column_descents histogram of one length per time, and positive "
                                 "scale, cell_size and tank_length");
    return d;
}

std::optional<ColumnDisorder> column_disorder_of(const std::vector<SphRun> &runs,
                                                 const std::vector<SphRun> &order_runs) {
    if (runs.empty())
        return std::nullopt;
    const std::vector<SphRun> &columns_of = order_runs.empty() ? runs : order_runs;
    for (const auto *set : {&runs, &columns_of})
        for (const auto &r : *set)
            for (const auto &iv : r.intervals)
                if (iv.column_interactions.empty())
                    return std::nullopt;
    const SphRun &first = columns_of.front();
    ColumnDisorder d;
    d.scale = first.config.scale;
    d.cell_size = first.config.cell_size;
    d.tank_length = first.config.tank_length;
    const std::size_t cols = first.intervals.front().column_interactions.size();
    for (const auto &iv : first.intervals)
        d.times_s.push_back(iv.time_s);
    auto same_record = [&](const SphRun &r) {
        if (r.intervals.size() != d.times_s.size() || r.config.scale != d.scale ||
            r.intervals.front().column_interactions.size() != cols)
            return false;
        for (std::size_t k = 0; k < r.intervals.size(); ++k)
            if (std::abs(r.intervals[k].time_s - d.times_s[k]) > 1e-9 * d.times_s.back())
                return false;
        return true;
    };
    for (const auto *set : {&runs, &columns_of})
        for (const auto &r : *set)
            if (!same_record(r))
                throw std::invalid_argument("column_disorder_of: runs of different record "
                                            "times, scales or columns");
    d.interactions.assign(d.times_s.size(), std::vector<double>(cols, 0.0));
    d.descents = d.interactions;
    for (const auto &r : columns_of) {
        if (!order_runs.empty())
            d.order_source += (d.order_source.empty() ? "" : ", ") + r.path;
        for (std::size_t k = 0; k < r.intervals.size(); ++k)
            for (std::size_t c = 0; c < cols; ++c) {
                const double n = double(columns_of.size());
                d.interactions[k][c] += r.intervals[k].column_interactions[c] / n;
                d.descents[k][c] += r.intervals[k].column_descents[c] / n;
            }
    }
    std::vector<std::vector<double>> X;
    std::vector<double> y;
    std::vector<int> classes;
    for (std::size_t run = 0; run < runs.size(); ++run) {
        const SphRun &r = runs[run];
        d.source += (d.source.empty() ? "" : ", ") + r.path;
        // Another grid's descents are read over this run's slabs: equal ones only.
        if (!order_runs.empty() && r.config.decomposition != "equal")
            continue;
        const double half = 0.5 * r.intervals.back().time_s;
        for (std::size_t k = 0; k < r.intervals.size(); ++k) {
            const auto &iv = r.intervals[k];
            if (iv.time_s < half)
                continue;
            double all = 0;
            for (const auto &rk : iv.ranks)
                all += rk.interactions;
            const std::vector<int> cuts =
                sph::equal_cuts(static_cast<int>(iv.ranks.size()), static_cast<int>(cols));
            // The ranks holding the water: a rank with a few front particles costs its fixed
            // part, not its interactions.
            for (std::size_t q = 0; q < iv.ranks.size(); ++q) {
                const auto &rk = iv.ranks[q];
                if (!(rk.steps >= 1 && rk.field_mean > 0 && rk.interactions >= 0.1 * all &&
                      rk.interactions > 0))
                    continue;
                double D = rk.descents / rk.interactions;
                if (!order_runs.empty()) {
                    double i = 0, dd = 0;
                    for (int c = cuts[q]; c < cuts[q + 1]; ++c) {
                        i += d.interactions[k][static_cast<std::size_t>(c)];
                        dd += d.descents[k][static_cast<std::size_t>(c)];
                    }
                    if (!(i > 0))
                        continue;
                    D = dd / i;
                }
                X.push_back({1.0, D});
                y.push_back(rk.compute_s() / rk.steps / rk.interactions);
                classes.push_back(static_cast<int>(run));
            }
        }
    }
    if (y.size() < 4)
        return std::nullopt;
    try {
        const LevelledFit f = fit_levelled(X, y, {"const", "descents_per_interaction"}, classes);
        d.intercept_s = f.fit.coef[0];
        d.slope_s = f.fit.coef[1];
        d.intercept_se_s = f.fit.se[0];
        d.slope_se_s = f.fit.se[1];
        d.r2 = f.fit.r2;
        d.points = f.fit.points;
    } catch (const std::invalid_argument &) {
        return std::nullopt;
    }
    return d;
}

// The runs with each interval's times divided by its speed gauge over the run's whole (the
// median over +-half_window intervals, SphRun::interval_gauges_s): the run's
// level stays, a spell within it goes. The cost line over the memory order is fitted within
// runs (one level per run) on the one long run that spans the order, and a spell of a slow
// host inside it (gauge 1.3-1.45 times the run's for a few intervals) flattened the line to
// R^2 0.002 in a session 91 job, which then predicted every slab at the whole water's order
// (model/NOTES.md, session 91). Runs without gauge samples stay as they are.
std::vector<SphRun> within_run_speed(std::vector<SphRun> runs, int half_window) {
    for (auto &r : runs) {
        const double whole = r.gauge_per_sample_s();
        const auto around = r.interval_gauges_s(half_window);
        if (!(whole > 0) || around.size() != r.intervals.size() ||
            std::any_of(around.begin(), around.end(), [](double g) { return !(g > 0); }))
            continue;
        std::vector<double> inverse;
        for (double g : around)
            inverse.push_back(whole / g);
        r.scale_times(inverse);
    }
    return runs;
}

std::vector<SphRun> within_run_kernel_speed(std::vector<SphRun> runs) {
    auto kernel_per_interaction = [](const RankStats &rk) {
        const double n = rk.steps * rk.interactions;
        return n > 0 ? rk.timer("comp_s") / n : 0.0;
    };
    for (auto &r : runs) {
        std::vector<double> k;
        for (const auto &iv : r.intervals)
            for (const auto &rk : iv.ranks)
                if (const double c = kernel_per_interaction(rk); c > 0)
                    k.push_back(c);
        if (k.empty())
            continue;
        const double level = median(k);
        for (auto &iv : r.intervals)
            for (auto &rk : iv.ranks)
                if (const double c = kernel_per_interaction(rk); c > 0)
                    rk.scale_times(level / c);
    }
    return runs;
}

} // namespace sphperf::model
