#include "sphperf/model/workload.hpp"

#include "sphperf/errors.hpp"
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/domain.hpp"
#include "sphperf/sph/setup.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
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
