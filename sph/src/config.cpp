#include "sphperf/sph/config.hpp"

#include "sphperf/errors.hpp"

#include <cmath>
#include <sstream>

namespace sphperf::sph {

namespace {
template <class E, std::size_t N>
E parse_enum(std::string_view what, std::string_view s,
             const std::pair<std::string_view, E> (&names)[N]) {
    std::string expected;
    for (const auto &[name, value] : names) {
        if (name == s)
            return value;
        expected += (expected.empty() ? "" : ", ") + std::string(name);
    }
    throw UsageError("unknown " + std::string(what) + " '" + std::string(s) +
                     "', expected one of " + expected);
}
template <class E, std::size_t N>
std::string_view name_of(E e, const std::pair<std::string_view, E> (&names)[N]) {
    for (const auto &[name, value] : names)
        if (value == e)
            return name;
    return "unknown";
}

constexpr std::pair<std::string_view, Setup> setups[] = {
    {"dambreak", Setup::dambreak}, {"still", Setup::still}, {"column", Setup::column}};
constexpr std::pair<std::string_view, GridKind> grids[] = {
    {"list", GridKind::list}, {"table", GridKind::table}, {"sorted", GridKind::sorted}};
constexpr std::pair<std::string_view, BoundaryKind> boundaries[] = {
    {"mirror", BoundaryKind::mirror}, {"fixed", BoundaryKind::fixed}};
constexpr std::pair<std::string_view, Decomposition> decompositions[] = {
    {"equal", Decomposition::equal}, {"balanced", Decomposition::balanced}};
constexpr std::pair<std::string_view, HaloTransport> halo_transports[] = {
    {"messages", HaloTransport::messages}, {"window", HaloTransport::window}};

// Thesis dimensions at scale 1 (3.1).
constexpr double tank_length_m = 3.22;
constexpr double dam_width_m = 1.2;
constexpr double dam_height_m = 0.6;
constexpr double ceiling_factor = 1.5;

// Particles on a closed interval of length `extent` at spacing delta; the tolerance keeps
// 1.2 / 0.01 = 119.99999999999999 from losing a particle to rounding.
int lattice_count(double extent, double delta) {
    return 1 + static_cast<int>(std::floor(extent / delta + 1e-9));
}
} // namespace

Setup parse_setup(std::string_view s) {
    return parse_enum("setup", s, setups);
}
GridKind parse_grid(std::string_view s) {
    return parse_enum("grid", s, grids);
}
BoundaryKind parse_boundary(std::string_view s) {
    return parse_enum("boundary", s, boundaries);
}
Decomposition parse_decomposition(std::string_view s) {
    return parse_enum("decomposition", s, decompositions);
}
std::string_view to_string(Decomposition d) {
    return name_of(d, decompositions);
}
HaloTransport parse_halo_transport(std::string_view s) {
    return parse_enum("halo transport", s, halo_transports);
}
std::string_view to_string(HaloTransport t) {
    return name_of(t, halo_transports);
}
FaultInjection parse_fault(std::string_view s) {
    const std::string text(s);
    const auto bad = [&] {
        return UsageError("SPHPERF_INJECT_FAULT='" + text +
                          "': expected KIND:RANK:STEP with KIND throw, nan or leak, RANK >= 0, "
                          "STEP >= 1");
    };
    const auto a = text.find(':'), b = text.find(':', a == std::string::npos ? a : a + 1);
    if (a == std::string::npos || b == std::string::npos)
        throw bad();
    FaultInjection f;
    const std::string kind = text.substr(0, a);
    if (kind == "throw")
        f.kind = FaultInjection::Kind::exception;
    else if (kind == "nan")
        f.kind = FaultInjection::Kind::nan;
    else if (kind == "leak")
        f.kind = FaultInjection::Kind::leak;
    else
        throw bad();
    try {
        std::size_t used = 0;
        const std::string rank = text.substr(a + 1, b - a - 1), step = text.substr(b + 1);
        f.rank = std::stoi(rank, &used);
        if (used != rank.size())
            throw bad();
        f.step = std::stoll(step, &used);
        if (used != step.size())
            throw bad();
    } catch (const std::logic_error &) { // stoi/stoll: not a number or out of range
        throw bad();
    }
    if (f.rank < 0 || f.step < 1)
        throw bad();
    return f;
}

std::string_view to_string(Setup s) {
    return name_of(s, setups);
}
std::string_view to_string(GridKind g) {
    return name_of(g, grids);
}
std::string_view to_string(BoundaryKind b) {
    return name_of(b, boundaries);
}

std::int64_t Config::total_steps() const {
    if (steps)
        return *steps;
    if (end_time)
        return static_cast<std::int64_t>(std::ceil(*end_time / dt - 1e-9));
    return 0;
}

Geometry make_geometry(const Config &cfg) {
    const Physics &ph = cfg.physics;
    Geometry g;
    g.cell_size = ph.cell_size();
    g.tank_length = tank_length_m * cfg.scale;
    const double delta = ph.delta;
    switch (cfg.setup) {
    case Setup::dambreak:
        g.dam_width = dam_width_m * cfg.scale;
        g.dam_height = dam_height_m * cfg.scale;
        // Particles are centres of delta x delta squares: the first row and column sit half a
        // spacing from the wall and floor surfaces, as wall particles sit half a spacing outside.
        g.dam_x0 = delta / 2;
        g.dam_y0 = delta / 2;
        g.fluid_columns = lattice_count(g.dam_width, delta);
        g.fluid_rows = lattice_count(g.dam_height, delta);
        break;
    case Setup::still:
        // Thesis 3.6.1: L = B - R_cell, half a cell from each wall and from the floor. Its
        // 19140 particles at scale 1 are 319 x 60: T / delta rows, one fewer than the dam
        // break's 1 + T / delta, so the column top stays at about T + R_cell / 2.
        g.dam_width = g.tank_length - g.cell_size;
        g.dam_height = dam_height_m * cfg.scale;
        g.dam_x0 = g.cell_size / 2;
        g.dam_y0 = g.cell_size / 2;
        g.fluid_columns = lattice_count(g.dam_width, delta);
        g.fluid_rows = lattice_count(g.dam_height, delta) - 1;
        break;
    case Setup::column:
        g.dam_width = cfg.column_width * cfg.scale;
        g.dam_height = 2 * g.dam_width;
        g.dam_x0 = delta / 2;
        g.dam_y0 = delta / 2;
        g.fluid_columns = lattice_count(g.dam_width, delta);
        g.fluid_rows = lattice_count(g.dam_height, delta);
        break;
    }
    g.ceiling = ceiling_factor * std::max(g.dam_height, dam_height_m * cfg.scale);
    g.cell_columns = static_cast<int>(std::ceil(g.tank_length / g.cell_size - 1e-9));
    g.cell_rows = static_cast<int>(std::ceil(g.ceiling / g.cell_size - 1e-9));
    return g;
}

void validate(const Config &cfg, const Geometry &geo, int ranks) {
    auto num = [](double v) {
        std::ostringstream s;
        s << v;
        return s.str();
    };
    if (!(cfg.scale > 0))
        throw UsageError("--scale " + num(cfg.scale) + " must be > 0");
    if (!(cfg.physics.delta > 0))
        throw UsageError("--delta " + num(cfg.physics.delta) + " must be > 0");
    if (!(cfg.dt > 0))
        throw UsageError("--dt " + num(cfg.dt) + " must be > 0");
    if (cfg.dt > cfg.physics.max_dt())
        throw UsageError("--dt " + num(cfg.dt) + " s is unstable: the CFL limit 0.4 h / c0 is " +
                         num(cfg.physics.max_dt()) + " s at delta " + num(cfg.physics.delta) +
                         " m; pass --dt <= " + num(cfg.physics.max_dt()));
    if (!(cfg.column_width > 0))
        throw UsageError("--column-width " + num(cfg.column_width) + " must be > 0");
    if (cfg.setup == Setup::column && geo.dam_width >= geo.tank_length)
        throw UsageError("--column-width " + num(cfg.column_width) +
                         " leaves no room for the surge in a tank " + num(geo.tank_length) +
                         " m long");
    if (!cfg.steps && !cfg.end_time)
        throw UsageError("give the run length with --steps N or --end-time SECONDS");
    if (cfg.steps && cfg.end_time)
        throw UsageError("--steps and --end-time are exclusive; give one");
    if (cfg.steps && *cfg.steps < 0)
        throw UsageError("--steps " + std::to_string(*cfg.steps) + " must be >= 0");
    if (cfg.end_time && !(*cfg.end_time >= 0))
        throw UsageError("--end-time " + num(*cfg.end_time) + " must be >= 0");
    if (cfg.interval < 1)
        throw UsageError("--interval " + std::to_string(cfg.interval) + " must be >= 1");
    if (cfg.threads < 0)
        throw UsageError("--threads " + std::to_string(cfg.threads) + " must be >= 1");
    if (cfg.vtk_every < 0 || (cfg.vtk_dir && cfg.vtk_every == 0))
        throw UsageError("--vtk-every " + std::to_string(cfg.vtk_every) +
                         " must be >= 1 when --vtk is given");
    if (cfg.checkpoint_every != 0 && !cfg.checkpoint_dir)
        throw UsageError("--checkpoint-every " + std::to_string(cfg.checkpoint_every) +
                         " needs --checkpoint DIR");
    if (cfg.checkpoint_dir && cfg.checkpoint_every < 1)
        throw UsageError("--checkpoint-every " + std::to_string(cfg.checkpoint_every) +
                         " must be >= 1");
    if (cfg.checkpoint_dir && cfg.checkpoint_every % cfg.interval != 0)
        throw UsageError("--checkpoint-every " + std::to_string(cfg.checkpoint_every) +
                         " must be a multiple of --interval " + std::to_string(cfg.interval) +
                         " (a checkpoint closes a report interval)");
    if (cfg.rebalance_every < 0 ||
        (cfg.decomposition == Decomposition::balanced && cfg.rebalance_every == 0))
        throw UsageError("--rebalance-every " + std::to_string(cfg.rebalance_every) +
                         " must be >= 1");
    if (cfg.decomposition == Decomposition::equal && (cfg.rebalance_every != 0 || cfg.cost_model))
        throw UsageError(std::string(cfg.cost_model ? "--model" : "--rebalance-every") +
                         " needs --decomposition balanced");
    if (cfg.overlap && cfg.grid != GridKind::sorted)
        throw UsageError("--overlap needs --grid sorted (the stored-list grids search all "
                         "neighbours at once, ghosts included), not --grid " +
                         std::string(to_string(cfg.grid)));
    if (cfg.reorder_every != 0 && cfg.grid != GridKind::sorted)
        throw UsageError("--reorder-every needs --grid sorted (the stored-list grids keep "
                         "indices across steps), not --grid " +
                         std::string(to_string(cfg.grid)));
    if (cfg.physics.shepard_every < 0)
        throw UsageError("--shepard-every " + std::to_string(cfg.physics.shepard_every) +
                         " must be >= 0 (0 disables the filter)");
    if (!(cfg.physics.alpha >= 0))
        throw UsageError("--alpha " + num(cfg.physics.alpha) + " must be >= 0");
    if (ranks > geo.cell_columns)
        throw UsageError(std::to_string(ranks) + " ranks exceed the " +
                         std::to_string(geo.cell_columns) +
                         " cell columns of the tank: each rank needs at least one column");
}

} // namespace sphperf::sph
