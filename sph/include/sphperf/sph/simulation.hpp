#pragma once
// One SPH run on one rank's slab, for any cell-grid scheme. step() reads as the method:
// kick-drift, migrate, boundary, ghosts, grid, neighbours, forces, kick.
#include "sphperf/sph/checkpoint.hpp"
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/domain.hpp"
#include "sphperf/sph/gauge.hpp"
#include "sphperf/sph/grid.hpp"
#include "sphperf/sph/integrator.hpp"
#include "sphperf/sph/output.hpp"
#include "sphperf/sph/physics.hpp"
#include "sphperf/sph/record.hpp"
#include "sphperf/sph/setup.hpp"
#include "sphperf/sph/sorted.hpp"
#include "sphperf/sph/timers.hpp"

#include <omp.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>
#include <functional>
#include <initializer_list>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

namespace sphperf::sph {

template <CellGrid Grid> class Simulation {
public:
    Simulation(const Config &cfg, const Geometry &geo, Domain &dom)
        : cfg_(cfg), geo_(geo), phys_(cfg.physics), dom_(dom), window_(dom.window(geo.cell_rows)) {
        dom_.attach_timers(&step_timers_);
        if constexpr (stored_lists)
            for (auto *v : {&acc_column_interactions_, &acc_column_descents_})
                v->assign(static_cast<std::size_t>(geo_.cell_columns), 0.0);
    }
    ~Simulation() { dom_.attach_timers(nullptr); }
    Simulation(const Simulation &) = delete;
    Simulation &operator=(const Simulation &) = delete;

    // `observe(step, particles)`, if given, is called after every step (tests, probes).
    using Observer = std::function<void(std::int64_t, const Particles &)>;
    RunRecord run(const Observer &observe = {});
    const Particles &particles() const { return p_; }

private:
    void load_initial();
    void start_fresh();
    std::int64_t resume(const std::filesystem::path &dir); // returns the checkpoint's step
    void write_checkpoint(std::int64_t step);
    void add_mirror_particles();
    void build_transients();
    void compute_forces();
    // --overlap: ghosts and their densities travel while the columns that need none are
    // computed; the same sums, in the same order, as build_transients() + compute_forces().
    void compute_forces_overlapped() requires OverlapGrid<Grid>;
    void step(std::int64_t s);
    // Balanced decomposition: the cost of every column under the current weights (all ranks),
    // and the re-cut to the cuts that balance it, with the migrations it takes.
    std::vector<double> column_costs() const;
    // The same from particle records every rank holds whole (no reduction).
    std::vector<double>
    column_costs(std::initializer_list<const std::vector<ParticleRecord> *> sets) const;
    void rebalance(std::int64_t step, const std::vector<double> &cost);
    void rebalance(std::int64_t step);
    bool rebalance_due(std::int64_t s) const {
        return cfg_.decomposition == Decomposition::balanced && s > 1 &&
               (s - 1) % cfg_.rebalance_every == 0;
    }
    void close_interval(std::int64_t step);
    void check_conservation(std::int64_t step) const;
    void check_state(std::int64_t step) const;
    [[noreturn]] void fail_state(std::int64_t step, std::size_t i, const std::string &what) const;
    void inject_fault(std::int64_t step);
    void sample_physics(double time);
    void write_snapshot(std::int64_t step);
    // Particles of kind k (fluid or wall) per global cell column, summed on rank 0.
    std::vector<double> column_histogram(bool fluid) const;
    static constexpr bool stored_lists = requires(typename Grid::Neighbours n) { n.descents_of; };
    // Stored lists: the last search's interactions and descents of every owned particle onto
    // its global column (the histogram's rule). Timed as output: it is the report's work.
    void add_column_counts() {
        if constexpr (stored_lists) {
            ScopedPhase t(step_timers_, Phase::output);
            for (std::size_t i = 0; i < std::min(nb_.particles(), p_.owned()); ++i) {
                const std::size_t c = column_of(p_.x[i]);
                acc_column_interactions_[c] += static_cast<double>(nb_.interactions_of(i));
                acc_column_descents_[c] += static_cast<double>(nb_.descents_of[i]);
            }
        }
    }
    std::size_t column_of(double x) const {
        return static_cast<std::size_t>(
            std::clamp(static_cast<int>(std::floor(x / geo_.cell_size)), 0, geo_.cell_columns - 1));
    }

    Config cfg_;
    Geometry geo_;
    Physics phys_;
    Domain &dom_;
    CellWindow window_;
    Grid grid_;
    Particles p_;
    typename Grid::Neighbours nb_; // the grid's own neighbourhood type
    PhaseTimers step_timers_, total_timers_;
    RankInterval acc_;
    // Stored-list grids: interactions and descents per global column over the interval.
    std::vector<double> acc_column_interactions_, acc_column_descents_;
    SpeedGauge gauge_;
    CoreLatencyGauge latency_;
    std::size_t last_mirrors_ = 0, last_ghosts_ = 0, last_exported_ = 0, last_migrated_ = 0;
    std::int64_t first_mirror_id_ = 0;
    std::vector<std::uint32_t> mirror_sources_;
    bool advance_density_ = false; // false only for the initial force evaluation
    long long initial_fluid_ = 0, initial_local_fluid_ = 0;
    double total_idle_ = 0, interactions_total_ = 0;
    std::int64_t snapshot_ = 0;
    std::int64_t last_checkpoint_ = -1; // step of the checkpoint the manifest names
    Snapshots snapshots_;
    RunRecord record_;
};

template <CellGrid Grid> void Simulation<Grid>::load_initial() {
    std::vector<ParticleRecord> fluid = make_fluid(geo_, phys_);
    std::vector<ParticleRecord> walls;
    if (cfg_.boundary == BoundaryKind::fixed)
        walls = make_walls(geo_, phys_, static_cast<std::int64_t>(fluid.size()));
    first_mirror_id_ = static_cast<std::int64_t>(fluid.size() + walls.size());
    if (cfg_.decomposition == Decomposition::balanced) {
        // Every rank holds the whole initial state here, so the first cut needs no exchange.
        rebalance(0, column_costs({&fluid, &walls}));
    }
    p_.reserve(2 * (fluid.size() + walls.size()) / static_cast<std::size_t>(dom_.ranks()));
    for (const auto *set : {&fluid, &walls})
        for (const auto &r : *set)
            if (dom_.slab().owns(r.x))
                p_.add_owned(r);
    initial_local_fluid_ = static_cast<long long>(p_.fluid());
    initial_fluid_ = dom_.sum(initial_local_fluid_);
    record_.fluid_particles = static_cast<std::int64_t>(fluid.size());
    record_.wall_particles = static_cast<std::int64_t>(walls.size());
}

// Mirror particles (mirror boundary), then ghosts from the neighbouring slabs.
template <CellGrid Grid> void Simulation<Grid>::add_mirror_particles() {
    ScopedPhase t(step_timers_, Phase::boundary);
    last_mirrors_ = cfg_.boundary == BoundaryKind::mirror
                        ? add_mirrors(p_, geo_, phys_, first_mirror_id_, mirror_sources_)
                        : 0;
}

template <CellGrid Grid> void Simulation<Grid>::build_transients() {
    add_mirror_particles();
    const ExchangeCounts g = dom_.exchange_ghosts(p_); // times its own wait, comm and pack
    last_ghosts_ = g.received;
    last_exported_ = g.sent;
}

template <CellGrid Grid> void Simulation<Grid>::compute_forces() {
    {
        ScopedPhase t(step_timers_, Phase::grid);
        grid_.update(p_, window_);
    }
    {
        ScopedPhase t(step_timers_, Phase::pairs);
        build_neighbours(grid_, p_, window_, phys_.cell_size(), nb_);
    }
    // The stored-list searches time their id sort apart: it is the price of sums in id order,
    // not of finding neighbours.
    step_timers_.add(Phase::pairs, -nb_.counts.sort_s);
    step_timers_.add(Phase::idsort, nb_.counts.sort_s);
    // Density advances with the half-step velocities (leapfrog for the acoustic pair), then the
    // copies of it held by mirrors and ghosts follow, then pressure and momentum use it. The
    // initial evaluation keeps the density as set up.
    if constexpr (SweepingGrid<Grid>) {
        // Without mirrors, the steps below in one sweep over the columns (sorted.hpp
        // sweep_forces), the ghosts' densities exchanged once every density pass is done. The
        // exchange books its own time, which the compute's does not keep.
        if (advance_density_ && mirror_sources_.empty()) {
            double exchange_s = 0;
            {
                ScopedPhase t(step_timers_, Phase::comp);
                sweep_forces(p_, nb_, phys_, 0.5 * cfg_.dt, cfg_.dt, [&] {
                    if (dom_.ranks() == 1)
                        return;
                    const double t0 = wall_seconds();
                    dom_.refresh_ghost_density(p_);
                    exchange_s = wall_seconds() - t0;
                    equation_of_state(p_, phys_, dom_.ghosts_begin(), p_.size());
                    grid_.refresh_ghost_density(p_);
                });
            }
            step_timers_.add(Phase::comp, -exchange_s);
            return;
        }
    }
    if (advance_density_) {
        {
            ScopedPhase t(step_timers_, Phase::comp);
            // The rate at the middle of the drift (separations half a step back along the
            // half-step velocities): second order (tests/integration/test_sph_state.cpp).
            continuity(p_, nb_, phys_, 0.5 * cfg_.dt);
            advance_density(p_, cfg_.dt);
            refresh_mirrors(p_, p_.owned(), mirror_sources_);
        }
        dom_.refresh_ghost_density(p_);
    }
    ScopedPhase t(step_timers_, Phase::comp);
    equation_of_state(p_, phys_);
    momentum(p_, nb_, phys_);
}

template <CellGrid Grid>
void Simulation<Grid>::compute_forces_overlapped() requires OverlapGrid<Grid> {
    add_mirror_particles();
    const GhostsInFlight coming = dom_.begin_ghosts(p_);
    {
        ScopedPhase t(step_timers_, Phase::grid);
        grid_.update(p_, window_, coming.from_west, coming.from_east);
    }
    {
        ScopedPhase t(step_timers_, Phase::pairs);
        build_neighbours(grid_, p_, window_, phys_.cell_size(), nb_);
    }
    const ColumnSet inner = grid_.columns_without_ghosts(), edges = inner.complement();
    const double back = 0.5 * cfg_.dt; // the rate at the middle of the drift (compute_forces)
    // Without mirrors the interior is swept as compute_forces sweeps (both passes; the forces of
    // its columns beside the edges wait), else only its density pass runs here.
    bool sweep = false;
    if constexpr (SweepingGrid<Grid>)
        sweep = mirror_sources_.empty();
    DensityCounts counts;
    {
        ScopedPhase t(step_timers_, Phase::comp);
        if constexpr (SweepingGrid<Grid>)
            if (sweep)
                counts = sweep_columns(p_, nb_, phys_, back, cfg_.dt, inner);
        if (!sweep)
            counts = continuity_columns(p_, nb_, phys_, back, inner);
    }
    const ExchangeCounts g = dom_.finish_ghosts(p_);
    last_ghosts_ = g.received;
    last_exported_ = g.sent;
    const std::size_t first_ghost = dom_.ghosts_begin();
    {
        ScopedPhase t(step_timers_, Phase::grid);
        grid_.add_ghosts(p_, first_ghost);
    }
    {
        ScopedPhase t(step_timers_, Phase::comp);
        counts += continuity_columns(p_, nb_, phys_, back, edges);
        nb_.counts = counts.counts();
        if constexpr (SweepingGrid<Grid>)
            if (sweep)
                advance_columns(p_, nb_, phys_, cfg_.dt, edges);
        if (!sweep) {
            advance_density(p_, cfg_.dt);
            refresh_mirrors(p_, p_.owned(), mirror_sources_);
        }
    }
    dom_.begin_ghost_density(p_);
    {
        ScopedPhase t(step_timers_, Phase::comp);
        if constexpr (SweepingGrid<Grid>)
            if (sweep)
                force_held_columns(p_, nb_, phys_); // the interior's beside the edges
        if (!sweep) {
            equation_of_state(p_, phys_, 0, first_ghost);
            grid_.refresh_density(p_); // the ghosts' entries are stale until their refresh below
            momentum_columns(p_, nb_, phys_, inner);
        }
    }
    dom_.finish_ghost_density(p_);
    ScopedPhase t(step_timers_, Phase::comp);
    equation_of_state(p_, phys_, first_ghost, p_.size());
    grid_.refresh_ghost_density(p_);
    momentum_columns(p_, nb_, phys_, edges);
}

template <CellGrid Grid> std::vector<double> Simulation<Grid>::column_costs() const {
    std::vector<double> cost(static_cast<std::size_t>(geo_.cell_columns), 0.0);
    for (std::size_t i = 0; i < p_.owned(); ++i)
        cost[column_of(p_.x[i])] += i < p_.fluid() ? cfg_.balance.fluid : cfg_.balance.walls;
    dom_.sum_all(cost);
    return cost;
}

template <CellGrid Grid>
std::vector<double> Simulation<Grid>::column_costs(
    std::initializer_list<const std::vector<ParticleRecord> *> sets) const {
    std::vector<double> cost(static_cast<std::size_t>(geo_.cell_columns), 0.0);
    for (const auto *set : sets)
        for (const auto &r : *set)
            cost[column_of(r.x)] += r.kind == Kind::fluid ? cfg_.balance.fluid : cfg_.balance.walls;
    return cost;
}

template <CellGrid Grid> void Simulation<Grid>::rebalance(std::int64_t step) {
    rebalance(step, column_costs());
}

// Moves the cuts and every particle to its new owner, then starts the grid afresh on the new
// window (the sums run in id order, so the trajectory is unchanged). Its time and messages are
// its own: the exchange phases and the per-step message tally (empty at the start of a step,
// where a re-cut happens) do not see them. `cost` is every column's, the same on all ranks.
template <CellGrid Grid>
void Simulation<Grid>::rebalance(std::int64_t step, const std::vector<double> &cost) {
    const double t0 = wall_seconds();
    const auto cuts = balanced_cuts(cost, dom_.ranks());
    const double mean = std::accumulate(cost.begin(), cost.end(), 0.0) / dom_.ranks();
    auto imbalance = [&](const std::vector<int> &c) {
        return mean > 0 ? max_slab_cost(cost, c) / mean : 1.0;
    };
    RebalanceRecord r;
    r.step = step;
    r.imbalance_before = imbalance(dom_.slab().cuts);
    r.imbalance_after = imbalance(cuts);
    dom_.attach_timers(nullptr);
    const auto moved = static_cast<long long>(
        dom_.rebalance(p_, cuts, [this](std::int64_t id) { grid_.forget(id); }).sent);
    dom_.attach_timers(&step_timers_);
    (void)dom_.take_tally();
    grid_ = Grid{};
    window_ = dom_.window(geo_.cell_rows);
    const double seconds = wall_seconds() - t0;
    step_timers_.add(Phase::rebalance, seconds);
    r.cuts = dom_.slab().cuts;
    r.moved = static_cast<double>(dom_.sum(moved));
    r.seconds = dom_.max(seconds);
    record_.rebalances.push_back(std::move(r));
}

template <CellGrid Grid> void Simulation<Grid>::step(std::int64_t s) {
    // The threads' shares of the fluid in the kicks and the drift: the grid's blocks where it
    // has them (Cell+Sorted), so that each thread writes the lines it reads in its block.
    const auto split = [this] {
        if constexpr (requires { grid_.fluid_split(); })
            return grid_.fluid_split();
        else
            return std::span<const std::size_t>{};
    };
    {
        ScopedPhase t(step_timers_, Phase::integrate);
        half_kick(p_, cfg_.dt, split());
        drift(p_, cfg_.dt, split());
    }
    if (cfg_.boundary == BoundaryKind::mirror) {
        ScopedPhase t(step_timers_, Phase::boundary);
        acc_.reflected += static_cast<double>(reflect_at_walls(p_, geo_));
    }
    {
        ScopedPhase t(step_timers_, Phase::grid);
        grid_.remove_transient(p_, window_);
        p_.drop_transient();
    }
    if (rebalance_due(s))
        rebalance(s);
    last_migrated_ = dom_.migrate(p_, [this](std::int64_t id) { grid_.forget(id); }).sent;
    if constexpr (ReorderingGrid<Grid>) {
        if (cfg_.reorder_every > 0 && s % cfg_.reorder_every == 0) {
            ScopedPhase t(step_timers_, Phase::grid);
            grid_.reorder(p_, window_);
        }
    }
    bool overlapped = false;
    if constexpr (OverlapGrid<Grid>) {
        if (cfg_.overlap) {
            compute_forces_overlapped();
            overlapped = true;
        }
    }
    if (!overlapped) {
        build_transients();
        compute_forces();
    }
    ScopedPhase t(step_timers_, Phase::integrate);
    half_kick(p_, cfg_.dt, split());
}

template <CellGrid Grid> void Simulation<Grid>::sample_physics(double time) {
    double front = 0, mass = 0, ke = 0;
    for (std::size_t i = 0; i < p_.fluid(); ++i) {
        if (p_.y[i] < 5 * phys_.delta)
            front = std::max(front, p_.x[i]);
        mass += p_.mass[i];
        ke += 0.5 * p_.mass[i] * (p_.vx[i] * p_.vx[i] + p_.vy[i] * p_.vy[i]);
    }
    auto &s = record_.physics;
    s.time_s.push_back(time);
    s.front_x.push_back(dom_.max(front));
    s.mass.push_back(dom_.sum(mass));
    s.kinetic_energy.push_back(dom_.sum(ke));
}

template <CellGrid Grid> void Simulation<Grid>::check_conservation(std::int64_t step) const {
    const long long fluid = dom_.sum(static_cast<long long>(p_.fluid()));
    // Compensated (Neumaier) sum: a plain sum of 7e7 equal masses drifts by 1e-8 relative,
    // above the check's tolerance, with no particle lost.
    double mass = 0, carry = 0;
    for (std::size_t i = 0; i < p_.fluid(); ++i) {
        const double t = mass + p_.mass[i];
        carry += std::abs(mass) >= std::abs(p_.mass[i]) ? (mass - t) + p_.mass[i]
                                                        : (p_.mass[i] - t) + mass;
        mass = t;
    }
    mass = dom_.sum(mass + carry);
    const double expected_mass = static_cast<double>(initial_fluid_) * phys_.particle_mass();
    if (fluid == initial_fluid_ && std::abs(mass - expected_mass) <= 1e-9 * expected_mass)
        return;
    // Name the ranks whose holdings do not match what their migrations say they should hold.
    const std::vector<double> mine{
        static_cast<double>(p_.fluid()), static_cast<double>(initial_local_fluid_),
        static_cast<double>(dom_.sent_east() + dom_.sent_west()),
        static_cast<double>(dom_.received_east() + dom_.received_west())};
    const std::vector<double> all = dom_.gather(mine);
    std::string culprits;
    for (std::size_t r = 0; r * 4 < all.size(); ++r) {
        const double expected = all[4 * r + 1] + all[4 * r + 3] - all[4 * r + 2];
        if (all[4 * r] != expected)
            culprits += (culprits.empty() ? "" : ", ") + std::to_string(r);
    }
    throw std::runtime_error(
        "step " + std::to_string(step) + ": fluid particles " + std::to_string(initial_fluid_) +
        " -> " + std::to_string(fluid) + ", mass " + std::to_string(expected_mass) + " -> " +
        std::to_string(mass) + " kg" +
        (culprits.empty() ? std::string(" (no rank's migrations explain it)")
                          : " on rank(s) " + culprits + " (holdings differ from migrations)"));
}

// Every step, on this rank alone: a NaN spreads to every neighbour within a step or two, and a
// fluid particle through a wall is lost physics. Either stops the run at once, naming the step
// and the particle, with this rank's particles written out for inspection.
template <CellGrid Grid> void Simulation<Grid>::check_state(std::int64_t step) const {
    // What is wrong with particle i, first match in this order (nothing: nullptr).
    static constexpr const char *left_tank = "left the tank";
    auto fault = [this](std::size_t i) -> const char * {
        if (!std::isfinite(p_.x[i]) || !std::isfinite(p_.y[i]))
            return "a non-finite position";
        if (!std::isfinite(p_.vx[i]) || !std::isfinite(p_.vy[i]))
            return "a non-finite velocity";
        if (!std::isfinite(p_.rho[i]))
            return "a non-finite density";
        if (i < p_.fluid() && (p_.x[i] < 0 || p_.x[i] > geo_.tank_length || p_.y[i] < 0))
            return left_tank;
        return nullptr;
    };
    // Found in parallel (a serial pass took 2 % of a 2-thread Cell+Sorted step) as one flag,
    // branch-free so that the loop vectorises (a NaN fails every comparison); only then is the
    // first faulty particle in id order looked for, and named.
    const std::size_t owned = p_.owned(), fluid = p_.fluid();
    const double length = geo_.tank_length;
    constexpr double big = std::numeric_limits<double>::max();
    const double *px = p_.x.data(), *py = p_.y.data(), *vx = p_.vx.data(), *vy = p_.vy.data(),
                 *rho = p_.rho.data();
    // The fluid in the threads' shares of the kicks (the grid's blocks where it has them: the
    // lines were last written on the same core), the walls in static shares.
    std::span<const std::size_t> split;
    if constexpr (requires { grid_.fluid_split(); })
        split = grid_.fluid_split();
    unsigned any = 0;
    const auto scan = [&](std::size_t begin, std::size_t end) {
        unsigned bad = 0;
        for (std::size_t i = begin; i < end; ++i) {
            const double x = px[i], y = py[i];
            const unsigned finite = static_cast<unsigned>(std::abs(x) <= big) &
                                    static_cast<unsigned>(std::abs(y) <= big) &
                                    static_cast<unsigned>(std::abs(vx[i]) <= big) &
                                    static_cast<unsigned>(std::abs(vy[i]) <= big) &
                                    static_cast<unsigned>(std::abs(rho[i]) <= big);
            const unsigned inside =
                static_cast<unsigned>(i >= fluid) |
                (static_cast<unsigned>(x >= 0) & static_cast<unsigned>(x <= length) &
                 static_cast<unsigned>(y >= 0));
            bad |= (finite & inside) ^ 1u;
        }
        return bad;
    };
#pragma omp parallel reduction(| : any)
    {
        const auto [f0, f1] = fluid_share(p_, split, static_share(fluid));
        const auto [w0, w1] = static_share(owned - fluid);
        any |= scan(f0, f1) | scan(fluid + w0, fluid + w1);
    }
    if (any == 0)
        return;
    std::size_t first = 0;
    while (first < owned && !fault(first))
        ++first;
    // The flag's tests are fault()'s; a flag without a faulty particle is a bug here, not a
    // particle past the owned ones to name.
    if (first == owned)
        throw std::logic_error("check_state: the state flag found a fault that no particle has");
    const char *what = fault(first);
    fail_state(step, first,
               what == left_tank ? std::string(left_tank) + " (0 <= x <= " +
                                       std::to_string(geo_.tank_length) + " m, y >= 0)"
                                 : std::string(what));
}

template <CellGrid Grid>
void Simulation<Grid>::fail_state(std::int64_t step, std::size_t i, const std::string &what) const {
    const std::filesystem::path dir =
        cfg_.vtk_dir
            ? *cfg_.vtk_dir
            : (cfg_.report && !cfg_.report->parent_path().empty() ? cfg_.report->parent_path()
                                                                  : ".");
    char name[64];
    std::snprintf(name, sizeof name, "sph_failure_step%lld_r%03d.vtu", static_cast<long long>(step),
                  dom_.rank());
    std::string where;
    try {
        write_vtu(dir / name, p_, dom_.rank());
        where = "this rank's particles are in " + (dir / name).string();
    } catch (const std::exception &e) {
        where = e.what();
    }
    char state[160];
    std::snprintf(state, sizeof state, "x %.6g y %.6g vx %.6g vy %.6g rho %.6g", p_.x[i], p_.y[i],
                  p_.vx[i], p_.vy[i], p_.rho[i]);
    throw std::runtime_error(
        "step " + std::to_string(step) + ": " + (i < p_.fluid() ? "fluid" : "wall") +
        " particle id " + std::to_string(p_.id[i]) + " has " + what + " (" + state + "); " + where);
}

template <CellGrid Grid> void Simulation<Grid>::inject_fault(std::int64_t step) {
    if (cfg_.fault->kind == FaultInjection::Kind::nan && p_.owned() > 0) {
        p_.vx[0] = std::numeric_limits<double>::quiet_NaN();
        return;
    }
    if (cfg_.fault->kind == FaultInjection::Kind::leak && p_.fluid() > 0) {
        p_.y[0] = -1.0;
        return;
    }
    throw std::runtime_error("step " + std::to_string(step) +
                             ": injected fault (SPHPERF_INJECT_FAULT)");
}

template <CellGrid Grid> std::vector<double> Simulation<Grid>::column_histogram(bool fluid) const {
    std::vector<double> columns(static_cast<std::size_t>(geo_.cell_columns), 0.0);
    const std::size_t begin = fluid ? 0 : p_.fluid(), end = fluid ? p_.fluid() : p_.owned();
    for (std::size_t i = begin; i < end; ++i)
        columns[static_cast<std::size_t>(std::clamp(
            static_cast<int>(std::floor(p_.x[i] / geo_.cell_size)), 0, geo_.cell_columns - 1))] +=
            1;
    dom_.sum_to_root(columns);
    return columns;
}

// This process's resident set now (/proc/self/statm, second field, in pages); 0 if unreadable.
inline double resident_bytes() {
    std::FILE *f = std::fopen("/proc/self/statm", "r");
    if (!f)
        return 0;
    long long size = 0, resident = 0;
    const int n = std::fscanf(f, "%lld %lld", &size, &resident);
    std::fclose(f);
    return n == 2 ? static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) : 0;
}

template <CellGrid Grid> void Simulation<Grid>::close_interval(std::int64_t step) {
    acc_.field = static_cast<double>(p_.fluid());
    acc_.rss_bytes = resident_bytes();
    acc_.probe_shift_s = dom_.probe_latency();
    for (std::size_t i = 0; i < p_.fluid(); ++i)
        if (p_.x[i] < 0 || p_.x[i] > geo_.tank_length || p_.y[i] < 0)
            acc_.escaped += 1;
    const double n = std::max(acc_.steps, 1.0);
    RankInterval out = acc_;
    for (double *v : {&out.virtual_, &out.ghost, &out.pairs, &out.interactions, &out.descents,
                      &out.exported, &out.cell_moves, &out.field_mean})
        *v /= n;
    const auto packed = out.pack();
    const auto all = dom_.gather(std::vector<double>(packed.begin(), packed.end()));
    std::vector<double> columns = column_histogram(true);
    for (auto *v : {&acc_column_interactions_, &acc_column_descents_}) {
        for (double &x : *v)
            x /= n;
        if (!v->empty())
            dom_.sum_to_root(*v);
    }
    if (dom_.rank() == 0) {
        IntervalRecord rec{step,
                           static_cast<double>(step) * cfg_.dt,
                           std::move(columns),
                           {},
                           acc_column_interactions_,
                           acc_column_descents_};
        for (std::size_t r = 0; r < static_cast<std::size_t>(dom_.ranks()); ++r)
            rec.ranks.push_back(RankInterval::unpack(&all[r * RankInterval::fields]));
        record_.intervals.push_back(std::move(rec));
    }
    acc_ = RankInterval{};
    for (auto *v : {&acc_column_interactions_, &acc_column_descents_})
        std::fill(v->begin(), v->end(), 0.0);
    check_conservation(step);
}

template <CellGrid Grid> void Simulation<Grid>::write_snapshot(std::int64_t step) {
    ScopedPhase t(step_timers_, Phase::output);
    snapshots_.write(*cfg_.vtk_dir, snapshot_++, static_cast<double>(step) * cfg_.dt, p_,
                     dom_.rank(), dom_.ranks());
}

template <CellGrid Grid> void Simulation<Grid>::start_fresh() {
    load_initial();
    build_transients();
    compute_forces(); // accelerations of the initial state; density stays as set up
    advance_density_ = true;
    sample_physics(0.0);
    record_.initial_columns = column_histogram(true);
    record_.wall_columns = column_histogram(false);
    if (cfg_.vtk_dir)
        write_snapshot(0);
}

// The state after the checkpoint's step. At the rank count that wrote it, every rank takes back
// its own particles (transient ones too) and its grid as they were, so the run goes on exactly
// as if never stopped, counters included. At another rank count the owned particles of all
// files are dealt out to the new slabs (fluid first, each kind in the saved order) and the grid
// starts afresh: the physics is the same wherever the sums run in a fixed order.
template <CellGrid Grid> std::int64_t Simulation<Grid>::resume(const std::filesystem::path &dir) {
    const Manifest m = read_manifest(dir); // verified whole by rank 0 before the run
    auto read_rank = [&](int r) {
        const auto path = dir / m.files.at(static_cast<std::size_t>(r)).name;
        return deserialise_rank(read_file(path), path.string());
    };
    const auto record_path = dir / m.files.back().name;
    RecordSoFar so_far = deserialise_record(read_file(record_path), record_path.string());
    record_.fluid_particles = so_far.fluid_particles;
    record_.wall_particles = so_far.wall_particles;
    record_.initial_columns = std::move(so_far.initial_columns);
    record_.physics = std::move(so_far.physics);
    if (dom_.rank() == 0)
        record_.intervals = std::move(so_far.intervals);
    record_.restarted_from_step = m.step;
    record_.restarted_from = dir;
    first_mirror_id_ = so_far.fluid_particles + so_far.wall_particles;
    record_.rebalances = m.rebalances;
    const auto saved_cuts = m.cuts.empty() ? equal_cuts(m.ranks, geo_.cell_columns) : m.cuts;
    const bool same_slabs =
        m.ranks == dom_.ranks() && (cfg_.decomposition == Decomposition::balanced ||
                                    saved_cuts == equal_cuts(m.ranks, geo_.cell_columns));
    if (same_slabs) {
        // The slabs as saved (nothing is held yet, so nothing moves), then each rank's state.
        dom_.rebalance(p_, saved_cuts, [](std::int64_t) {});
        window_ = dom_.window(geo_.cell_rows);
        const RankState s = read_rank(dom_.rank());
        s.restore(p_);
        grid_.restore_state(s.grid_state);
        total_idle_ = s.idle_s;
        interactions_total_ = s.interactions_total;
        for (std::size_t k = 0; k < s.timers.size() && k < total_timers_.values().size(); ++k)
            total_timers_.add(static_cast<Phase>(k), s.timers[k]);
    } else {
        std::vector<ParticleRecord> all;
        std::vector<double> ax, ay;
        for (int r = 0; r < m.ranks; ++r)
            read_rank(r).append_owned(all, ax, ay);
        if (cfg_.decomposition == Decomposition::balanced) {
            // Every rank holds every particle here: the cut needs no exchange.
            rebalance(m.step, column_costs({&all}));
        }
        for (const Kind kind : {Kind::fluid, Kind::boundary})
            for (std::size_t i = 0; i < all.size(); ++i)
                if (all[i].kind == kind && dom_.slab().owns(all[i].x)) {
                    p_.add_owned(all[i]);
                    p_.ax.back() = ax[i];
                    p_.ay.back() = ay[i];
                }
    }
    initial_local_fluid_ = static_cast<long long>(p_.fluid());
    initial_fluid_ = dom_.sum(initial_local_fluid_);
    if (initial_fluid_ != so_far.fluid_particles)
        throw std::runtime_error(dir.string() + ": the rank files hold " +
                                 std::to_string(initial_fluid_) + " fluid particles, the run " +
                                 std::to_string(so_far.fluid_particles));
    record_.wall_columns = column_histogram(false); // walls never move
    advance_density_ = true;
    last_checkpoint_ = m.step;
    snapshot_ = cfg_.vtk_dir ? m.step / cfg_.vtk_every + 1 : 0;
    return m.step;
}

// Every rank writes its file (temporary name, then rename); the gather that follows returns on
// rank 0 only once all have, and only then does the manifest move to this step.
template <CellGrid Grid> void Simulation<Grid>::write_checkpoint(std::int64_t step) {
    ScopedPhase t(step_timers_, Phase::output);
    const std::filesystem::path dir = *cfg_.checkpoint_dir;
    const std::string sub = step_dir_name(step);
    std::filesystem::create_directories(dir / sub);
    RankState s = RankState::of(p_);
    s.step = step;
    s.rank = dom_.rank();
    s.ranks = dom_.ranks();
    s.grid_state = grid_.save_state();
    s.idle_s = total_idle_;
    s.interactions_total = interactions_total_;
    const auto &tv = total_timers_.values();
    s.timers.assign(tv.begin(), tv.end());
    const std::string bytes = serialise(s);
    char name[32];
    std::snprintf(name, sizeof name, "rank_%03d.bin", dom_.rank());
    write_atomically(dir / sub / name, bytes);
    const std::uint64_t h = fnv1a64(bytes);
    constexpr std::uint64_t low32 = 0xffffffffULL;
    const auto info = dom_.gather({static_cast<double>(bytes.size()), static_cast<double>(h >> 32),
                                   static_cast<double>(h & low32)});
    if (dom_.rank() != 0)
        return;
    Manifest m = manifest_for(cfg_, step, dom_.ranks());
    m.cuts = dom_.slab().cuts;
    m.rebalances = record_.rebalances;
    for (int r = 0; r < dom_.ranks(); ++r) {
        const double *v = &info[static_cast<std::size_t>(r) * 3];
        std::snprintf(name, sizeof name, "rank_%03d.bin", r);
        m.files.push_back(
            {sub + "/" + name, static_cast<std::uint64_t>(v[0]),
             hex64((static_cast<std::uint64_t>(v[1]) << 32) | static_cast<std::uint64_t>(v[2]))});
    }
    const std::string rec =
        serialise(RecordSoFar{record_.fluid_particles, record_.wall_particles,
                              record_.initial_columns, record_.intervals, record_.physics});
    write_atomically(dir / sub / "record.bin", rec);
    m.files.push_back({sub + "/record.bin", rec.size(), hex64(fnv1a64(rec))});
    // The checkpoint this one replaces: the previous one of this run, or the one a restart
    // came from when it writes into the same directory.
    std::int64_t previous = last_checkpoint_;
    try {
        previous = read_manifest(dir).step;
    } catch (const std::exception &) {
    }
    write_manifest(dir, m);
    if (previous >= 0 && previous != step) {
        std::error_code ec; // a leftover directory costs disk, not correctness
        std::filesystem::remove_all(dir / step_dir_name(previous), ec);
    }
    last_checkpoint_ = step;
}

template <CellGrid Grid> RunRecord Simulation<Grid>::run(const Observer &observe) {
    record_.config = cfg_;
    record_.geometry = geo_;
    record_.ranks = dom_.ranks();
    record_.threads = omp_get_max_threads();
    const std::int64_t steps = cfg_.total_steps();
    record_.steps = steps;
    const int physics_every = std::max(1, std::min(cfg_.interval, 100));

    const std::int64_t first = cfg_.restart_dir ? resume(*cfg_.restart_dir) : 0;
    if (!cfg_.restart_dir)
        start_fresh();
    step_timers_.reset();
    (void)dom_.take_tally();

    Progress progress(dom_.rank() == 0 && !cfg_.quiet, steps, cfg_.dt);
    dom_.barrier();
    const double start = wall_seconds();
    for (std::int64_t s = first + 1; s <= steps; ++s) {
        if (cfg_.speed_gauge_every > 0 && s % cfg_.speed_gauge_every == 0) {
            ScopedPhase t(step_timers_, Phase::gauge);
            acc_.gauge_cpu_s += gauge_.sample();
            acc_.gauge_samples += 1;
            if (const double rt = cfg_.core_latency_gauge
                                      ? latency_.sample()
                                      : std::numeric_limits<double>::quiet_NaN();
                std::isfinite(rt)) {
                acc_.core_round_trip_s += rt;
                acc_.core_round_trip_samples += 1;
            }
        }
        const double t0 = wall_seconds();
        step(s);
        if (cfg_.physics.shepard_every > 0 && s % cfg_.physics.shepard_every == 0) {
            ScopedPhase t(step_timers_, Phase::comp);
            shepard_filter(p_, nb_, phys_);
        }
        if (cfg_.fault && cfg_.fault->rank == dom_.rank() && cfg_.fault->step == s)
            inject_fault(s);
        {
            // Timed with the integrator (a pass over the owned particles): the model reads an
            // interval's time from the timers. What no phase holds is the run's own bookkeeping
            // (the record, the inline costing of shifts, each interval's probe and gathers):
            // 5-17 us a step on 2 ranks (model/NOTES.md, session 84).
            ScopedPhase t(step_timers_, Phase::integrate);
            check_state(s);
        }
        const double dt_wall = wall_seconds() - t0;
        if (p_.fluid() == 0) {
            acc_.idle_s += dt_wall;
            total_idle_ += dt_wall;
        }
        acc_.steps += 1;
        acc_.virtual_ += static_cast<double>(
            cfg_.boundary == BoundaryKind::mirror ? last_mirrors_ : p_.owned() - p_.fluid());
        acc_.ghost += static_cast<double>(last_ghosts_);
        acc_.pairs += static_cast<double>(nb_.counts.pairs);
        acc_.interactions += static_cast<double>(nb_.counts.interactions);
        acc_.descents += static_cast<double>(nb_.counts.descents);
        add_column_counts();
        interactions_total_ += static_cast<double>(nb_.counts.interactions);
        acc_.exported += static_cast<double>(last_exported_);
        acc_.migrated += static_cast<double>(last_migrated_);
        acc_.cell_moves += static_cast<double>(grid_.last_moves());
        acc_.field_mean += static_cast<double>(p_.fluid());
        const CommTally tally = dom_.take_tally();
        acc_.messages += tally.messages;
        acc_.message_bytes += tally.bytes;
        acc_.comm_predict_s += tally.predicted_s;
        acc_.comm_predict_exchange_s += tally.predicted_s;
        acc_.comm_hockney_s += tally.hockney_s;
        acc_.overlap_s += tally.overlap_s;
        acc_.hidden_predict_s += tally.hidden_predict_s;
        for (std::size_t k = 0; k < tally.shift_s.size(); ++k) {
            acc_.shift_comm_s[k] += tally.shift_s[k];
            acc_.shift_predict_s[k] += tally.shift_predict_s[k];
            acc_.shift_predict_own_kind_s[k] += tally.shift_predict_own_kind_s[k];
            acc_.segment_cpu_s[k] += tally.segment_cpu_s[k];
        }
        for (std::size_t k = 0; k < acc_.timers.size(); ++k)
            acc_.timers[k] += step_timers_.values()[k];
        for (std::size_t k = 0; k < acc_.timers.size(); ++k)
            total_timers_.add(static_cast<Phase>(k), step_timers_.values()[k]);
        step_timers_.reset();

        if (s % physics_every == 0 || s == steps)
            sample_physics(static_cast<double>(s) * cfg_.dt);
        if (s % cfg_.interval == 0 || s == steps)
            close_interval(s);
        if (cfg_.vtk_dir && s % cfg_.vtk_every == 0)
            write_snapshot(s);
        if (cfg_.checkpoint_dir && s % cfg_.checkpoint_every == 0)
            write_checkpoint(s);
        progress.update(s);
        if (observe)
            observe(s, p_);
    }
    dom_.complete_sends(); // --overlap leaves the last exchange's sends to complete
    dom_.barrier();
    record_.wall_s = wall_seconds() - start;
    progress.finish();
    if (steps == 0)
        check_conservation(0);

    record_.interactions_total = dom_.sum(interactions_total_);
    double virt = 0;
    for (const auto &iv : record_.intervals)
        for (const auto &r : iv.ranks)
            virt += r.virtual_ * r.steps;
    record_.mean_virtual = steps > 0 ? virt / static_cast<double>(steps) : 0;

    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    constexpr double kib = 1024.0;
    record_.peak_rss_bytes = dom_.gather({static_cast<double>(usage.ru_maxrss) * kib});
    const auto &tv = total_timers_.values();
    const auto timers = dom_.gather(std::vector<double>(tv.begin(), tv.end()));
    for (std::size_t r = 0; r * tv.size() < timers.size(); ++r) {
        std::array<double, static_cast<std::size_t>(Phase::count)> a{};
        std::copy_n(&timers[r * tv.size()], tv.size(), a.begin());
        record_.timers.push_back(a);
    }
    record_.idle_s = dom_.gather({total_idle_});
    record_.final_cuts = dom_.slab().cuts;
    if (cfg_.vtk_dir && dom_.rank() == 0)
        snapshots_.write_index(*cfg_.vtk_dir);
    return record_;
}

} // namespace sphperf::sph
