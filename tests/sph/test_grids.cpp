// All three grid schemes against an O(N^2) search, on random and lattice configurations with ghost
// columns, and the persistent table through moves, departures and transient particles.
#include "sphperf/sph/grid.hpp"
#include "sphperf/sph/integrator.hpp"
#include "sphperf/sph/physics.hpp"
#include "sphperf/sph/sorted.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>
#include <random>
#include <set>
#include <stdexcept>
#include <string>

using namespace sphperf::sph;

namespace {
constexpr double cell = 0.04;
using PairSet = std::set<std::pair<std::int64_t, std::int64_t>>;

// Ordered pairs (id_i, id_j) for owned i, as the neighbour list has them.
PairSet brute_force(const Particles &p) {
    PairSet s;
    for (std::size_t i = 0; i < p.owned(); ++i)
        for (std::size_t j = 0; j < p.size(); ++j) {
            if (i == j || !interacting(p.kind[i], p.kind[j]))
                continue;
            const double dx = p.x[i] - p.x[j], dy = p.y[i] - p.y[j];
            if (dx * dx + dy * dy < cell * cell)
                s.insert({p.id[i], p.id[j]});
        }
    return s;
}

PairSet from_list(const Particles &p, const NeighbourList &nl) {
    PairSet s;
    for (std::size_t i = 0; i < nl.particles(); ++i) {
        std::int64_t previous = -1;
        for (auto e = nl.offsets[i]; e < nl.offsets[i + 1]; ++e) {
            const auto j = nl.index[e];
            EXPECT_GT(p.id[j], previous) << "neighbours must be sorted by id";
            previous = p.id[j];
            s.insert({p.id[i], p.id[j]});
        }
    }
    return s;
}

// The OpenMP team size within a test: the one before comes back however the test ends (an
// ASSERT returns early).
class TeamSize {
public:
    TeamSize() = default;
    TeamSize(const TeamSize &) = delete;
    TeamSize &operator=(const TeamSize &) = delete;
    ~TeamSize() { omp_set_num_threads(before_); }
    void set(int threads) const { omp_set_num_threads(threads); }

private:
    int before_ = omp_get_max_threads();
};

// A slab owning columns 3..8 of a tank, ghosts in columns 2 and 9, rows -1..5.
const CellWindow window{cell, 2, 10, -1, 6};

Particles random_configuration(unsigned seed, int n_owned, int n_ghost) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> x_owned(3 * cell, 9 * cell), y(-cell, 6 * cell);
    std::uniform_real_distribution<double> x_west(2 * cell, 3 * cell), x_east(9 * cell, 10 * cell);
    Particles p;
    std::int64_t id = 0;
    for (int i = 0; i < n_owned; ++i) {
        const Kind k = i % 5 == 0 ? Kind::boundary : Kind::fluid;
        p.add_owned({x_owned(rng), y(rng), 0, 0, 1000, 0, 1, id++, k});
    }
    for (int i = 0; i < n_ghost; ++i) {
        const Kind k = i % 3 == 0 ? Kind::mirror : (i % 3 == 1 ? Kind::boundary : Kind::fluid);
        const double x = i % 2 ? x_west(rng) : x_east(rng);
        p.add_transient({x, y(rng), 0, 0, 1000, 0, 1, id++, k});
    }
    return p;
}

// Random velocities in [-1, 1] m/s and densities 1000 +- 10 (and with `one_mass` false
// masses 1 +- 0.2) for every particle.
void stir(Particles &p, unsigned seed, bool one_mass = true) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1);
    for (std::size_t i = 0; i < p.size(); ++i) {
        p.vx[i] = u(rng);
        p.vy[i] = u(rng);
        p.rho[i] = 1000 + 10 * u(rng);
        if (!one_mass)
            p.mass[i] = 1 + 0.2 * u(rng);
    }
}

// What the packing tests pack from: random owned particles, walls and ghosts, two owned
// particles at one position (in range, not packed), sorted.
struct PackingCase {
    Particles p = random_configuration(21, 700, 200);
    CellSorted g;
    PackingCase() {
        p.x[10] = p.x[11];
        p.y[10] = p.y[11];
        g.update(p, window);
    }
};

// The candidate ranges [b, e) of sorted positions around the cell that holds sorted position
// i, columns west to east (the ranges a particle of that cell packs).
std::vector<std::pair<std::size_t, std::size_t>> ranges_around(const CellSorted::View &v,
                                                               std::size_t i) {
    const int cells = v.cols * v.rows;
    const int cell_i = static_cast<int>(std::upper_bound(v.start, v.start + cells + 1,
                                                         static_cast<std::uint32_t>(i)) -
                                        v.start) -
                       1;
    const int col = cell_i / v.rows, row = cell_i % v.rows;
    const int r0 = std::max(row - CellSorted::rows_per_cell, 0);
    const int r1 = std::min(row + CellSorted::rows_per_cell, v.rows - 1);
    std::vector<std::pair<std::size_t, std::size_t>> ranges;
    for (int c = std::max(col - 1, 0); c <= std::min(col + 1, v.cols - 1); ++c)
        ranges.emplace_back(v.start[c * v.rows + r0], v.start[c * v.rows + r1 + 1]);
    return ranges;
}

template <class G> PairSet search(G &grid, const Particles &p) {
    NeighbourList nl;
    grid.update(p, window);
    find_neighbours(grid, p, window, cell, nl);
    return from_list(p, nl);
}
// Per cell of a sorted grid, the candidates its particles examine: its particles times the
// candidates in the ranges around it (the cost the thread blocks are cut at).
std::vector<double> candidates_examined(const CellSorted::View &v) {
    const int cells = v.cols * v.rows;
    std::vector<double> cost(static_cast<std::size_t>(cells), 0.0);
    for (int c = 0; c < cells; ++c) {
        const int col = c / v.rows, row = c % v.rows;
        const int r0 = std::max(row - CellSorted::rows_per_cell, 0);
        const int r1 = std::min(row + CellSorted::rows_per_cell, v.rows - 1);
        double candidates = 0;
        for (int k = std::max(col - 1, 0); k <= std::min(col + 1, v.cols - 1); ++k)
            candidates += v.start[k * v.rows + r1 + 1] - v.start[k * v.rows + r0];
        cost[static_cast<std::size_t>(c)] = (v.start[c + 1] - v.start[c]) * candidates;
    }
    return cost;
}
} // namespace

template <class G> class GridTest : public ::testing::Test {};
using Grids = ::testing::Types<CellList, CellTable, CellSorted>;
TYPED_TEST_SUITE(GridTest, Grids);

TYPED_TEST(GridTest, MatchesBruteForceOnRandomConfigurations) {
    for (unsigned seed = 1; seed <= 5; ++seed) {
        const Particles p = random_configuration(seed, 600, 150);
        TypeParam grid;
        const auto expected = brute_force(p);
        EXPECT_GT(expected.size(), 1000u);
        EXPECT_EQ(search(grid, p), expected) << "seed " << seed;
    }
}

TYPED_TEST(GridTest, MatchesBruteForceOnALatticeWithGhostColumns) {
    // Lattice points sit exactly on cell edges and at exactly one cell size apart: the
    // boundary cases of the cell index and of the strict distance test.
    Particles p;
    std::int64_t id = 0;
    for (int i = 0; i <= 24; ++i)
        for (int j = 0; j <= 12; ++j) {
            const double x = 3 * cell + i * cell / 4, y = j * cell / 4;
            p.add_owned({x, y, 0, 0, 1000, 0, 1, id++, j == 0 ? Kind::boundary : Kind::fluid});
        }
    for (int j = 0; j <= 12; ++j) {
        p.add_transient({3 * cell - cell / 4, j * cell / 4, 0, 0, 1000, 0, 1, id++, Kind::fluid});
        p.add_transient({9 * cell + cell / 2, j * cell / 4, 0, 0, 1000, 0, 1, id++, Kind::fluid});
    }
    TypeParam grid;
    EXPECT_EQ(search(grid, p), brute_force(p));
}

TYPED_TEST(GridTest, StaysExactAsParticlesMoveLeaveAndArrive) {
    Particles p = random_configuration(42, 400, 100);
    TypeParam grid;
    std::mt19937 rng(3);
    std::normal_distribution<double> step(0, cell / 3); // many cell changes per update
    for (int round = 0; round < 6; ++round) {
        ASSERT_EQ(search(grid, p), brute_force(p)) << "round " << round;
        grid.remove_transient(p, window);
        p.drop_transient();
        // Move everything, then one particle leaves and a new one arrives (migration).
        for (std::size_t i = 0; i < p.owned(); ++i) {
            p.x[i] = std::clamp(p.x[i] + step(rng), 3 * cell, 9 * cell - 1e-9);
            p.y[i] = std::clamp(p.y[i] + step(rng), -cell, 6 * cell);
        }
        grid.forget(p.id[7]);
        p.remove_owned(7);
        p.add_owned({5 * cell, cell, 0, 0, 1000, 0, 1, 10000 + round, Kind::fluid});
        std::uniform_real_distribution<double> gx(9 * cell, 10 * cell), gy(0, 5 * cell);
        for (int g = 0; g < 50; ++g)
            p.add_transient(
                {gx(rng), gy(rng), 0, 0, 1000, 0, 1, 20000 + 100 * round + g, Kind::fluid});
    }
}

// The stored lists' per-particle descents (the report adds them up per column for the model's
// per-rank memory order): they add up to the search's at 1 and 2 threads, and each particle's
// is fewer than its own list's entries.
template <class G> void check_particle_descents() {
    Particles p = random_configuration(7, 600, 150);
    // Shuffle the ids' memory order a little so that descents are not all zero.
    std::mt19937 rng(11);
    for (int k = 0; k < 200; ++k) {
        const auto a = rng() % p.owned(), b = rng() % p.owned();
        std::swap(p.id[a], p.id[b]);
    }
    const TeamSize team;
    for (int threads : {1, 2}) {
        team.set(threads);
        G grid;
        NeighbourList nl;
        grid.update(p, window);
        nl.counts = find_neighbours(grid, p, window, cell, nl);
        ASSERT_EQ(nl.descents_of.size(), p.owned());
        std::uint64_t sum = 0;
        for (std::size_t i = 0; i < p.owned(); ++i) {
            sum += nl.descents_of[i];
            EXPECT_LT(nl.descents_of[i], std::max<std::size_t>(nl.interactions_of(i), 1u)) << i;
        }
        EXPECT_EQ(sum, nl.counts.descents) << threads << " threads";
        EXPECT_GT(nl.counts.descents, 0u);
    }
}
TEST(StoredLists, CountDescentsPerParticle) {
    check_particle_descents<CellList>();
    check_particle_descents<CellTable>();
}

TEST(CellWindow, FilesOutsidePositionsInEdgeCells) {
    EXPECT_EQ(window.column_of(-5.0), 2);
    EXPECT_EQ(window.column_of(99.0), 9);
    EXPECT_EQ(window.row_of(-1.0), -1);
    EXPECT_EQ(window.row_of(99.0), 5);
    EXPECT_EQ(window.column_of(3 * cell), 3);
}

// Cell+Sorted's pair terms are computed in PairReal (single precision): their sums agree with
// the stored lists' double ones to this fraction of the largest |value| of the pass, its few
// units of float rounding, measured 6.7e-7 (density) and 1.1e-6 (forces); with double pair
// terms to 1e-12.
constexpr double pair_rounding = std::is_same_v<PairReal, float> ? 4e-6 : 1e-12;

// Cell+Sorted's drivers against the stored-list drivers on the same random configuration:
// the same physics summed in another order and precision, so equal to rounding; and the same
// counts.
// With one mass for every particle (every setup) the pair loops take it as a constant; with
// masses that differ they gather them: both paths against the stored-list drivers.
TEST(CellSorted, DriversMatchTheStoredListDrivers) {
    for (const bool one_mass : {true, false}) {
        SCOPED_TRACE(one_mass ? "one mass" : "masses differ");
        Physics phys;
        phys.h = cell / QuinticKernel::support_factor;
        Particles p = random_configuration(7, 600, 150);
        stir(p, 9, one_mass);
        equation_of_state(p, phys);
        Particles q = p;
        // Density rates and accelerations as Simulation computes them, through the grid's own
        // neighbourhood type.
        auto forces = [&](auto &grid, auto &nb, Particles &particles) {
            grid.update(particles, window);
            build_neighbours(grid, particles, window, cell, nb);
            continuity(particles, nb, phys, 1e-4); // separations half a step back, as in a run
            momentum(particles, nb, phys);
        };
        CellTable table;
        NeighbourList nl;
        forces(table, nl, p);
        CellSorted sorted;
        SortedNeighbours nb;
        forces(sorted, nb, q);
        EXPECT_EQ(sorted.view().common_mass, one_mass ? 1.0 : 0.0);
        EXPECT_EQ(nb.counts.interactions, nl.counts.interactions);
        EXPECT_EQ(nb.counts.pairs, nl.counts.pairs);
        double scale_drho = 0, scale_a = 0;
        for (std::size_t i = 0; i < p.owned(); ++i) {
            scale_drho = std::max(scale_drho, std::abs(p.drho[i]));
            scale_a = std::max(scale_a, std::hypot(p.ax[i], p.ay[i]));
        }
        ASSERT_GT(scale_drho, 0);
        double worst_drho = 0, worst_a = 0;
        for (std::size_t i = 0; i < p.owned(); ++i) {
            EXPECT_NEAR(q.drho[i], p.drho[i], pair_rounding * scale_drho) << i;
            EXPECT_NEAR(q.ax[i], p.ax[i], pair_rounding * scale_a) << i;
            EXPECT_NEAR(q.ay[i], p.ay[i], pair_rounding * scale_a) << i;
            worst_drho = std::max(worst_drho, std::abs(q.drho[i] - p.drho[i]) / scale_drho);
            worst_a = std::max(worst_a, std::hypot(q.ax[i] - p.ax[i], q.ay[i] - p.ay[i]) / scale_a);
        }
        std::printf("sorted against stored lists (%s): density rates to %.2g, accelerations to "
                    "%.2g of their largest\n",
                    one_mass ? "one mass" : "masses differ", worst_drho, worst_a);
        shepard_filter(p, nl, phys);
        shepard_filter(q, nb, phys);
        for (std::size_t i = 0; i < p.fluid(); ++i)
            EXPECT_NEAR(q.rho[i], p.rho[i], 1e-12 * p.rho[i]) << i;
    }
}

// Simulation sweeps where the grid's neighbourhood offers it, and only there.
static_assert(SweepingGrid<CellSorted>);
static_assert(!SweepingGrid<CellList> && !SweepingGrid<CellTable>);

// sweep_forces is continuity, the density advance, the equation of state and momentum in one
// sweep over the columns, each particle's sums the passes' own: bitwise the same rates,
// densities, pressures, accelerations and counts as the four steps apart, at 1 to 3 threads
// (the columns handed out in chunks; a run's edge columns wait for their neighbours). The
// multi-rank and --overlap sweeps are checked bitwise by test_sph_state.cpp.
TEST(CellSorted, SweepIsTheSeparateSteps) {
    Physics phys;
    phys.h = cell / QuinticKernel::support_factor;
    constexpr double dt = 1e-4;
    const TeamSize team;
    // In chunk order, and with every chunk a run of its own (its edge columns' forces then
    // wait for the neighbours and pack afresh).
    for (const int threads : {1, 2, 3})
        for (const bool from_back : {false, true}) {
            SCOPED_TRACE(std::to_string(threads) + " threads" +
                         (from_back ? ", from the back" : ""));
            team.set(threads);
            Particles p = random_configuration(11, 900, 0);
            stir(p, 4);
            equation_of_state(p, phys);
            Particles q = p;
            CellSorted apart, swept;
            SortedNeighbours na, ns;
            apart.update(p, window);
            build_neighbours(apart, p, window, cell, na);
            continuity(p, na, phys, 0.5 * dt);
            advance_density(p, dt);
            equation_of_state(p, phys);
            momentum(p, na, phys);
            swept.sweep_from_back = from_back;
            swept.update(q, window);
            build_neighbours(swept, q, window, cell, ns);
            sweep_forces(q, ns, phys, 0.5 * dt, dt);
            EXPECT_GT(na.counts.interactions, 0u);
            EXPECT_EQ(ns.counts.interactions, na.counts.interactions);
            EXPECT_EQ(ns.counts.pairs, na.counts.pairs);
            std::size_t moving = 0;
            for (std::size_t i = 0; i < p.owned(); ++i) {
                ASSERT_EQ(q.drho[i], p.drho[i]) << i;
                ASSERT_EQ(q.rho[i], p.rho[i]) << i;
                ASSERT_EQ(q.p[i], p.p[i]) << i;
                ASSERT_EQ(q.ax[i], p.ax[i]) << i;
                ASSERT_EQ(q.ay[i], p.ay[i]) << i;
                moving += p.ax[i] != 0;
            }
            EXPECT_GT(moving, p.owned() / 2); // the forces were computed, not left at 0
        }
}

// The packing of in-range candidates (vectorised where the build has AVX-512) against a plain
// filter of the same range: the same positions in the same order, the same separations to the
// bit, and the same counts; with coincident particles (in range, not packed), ghosts (remote)
// and walls (not packed for a wall's density pass), through whole vectors and tails.
TEST(CellSorted, PackedCandidatesAreTheFilteredRangeInOrder) {
    const PackingCase sorted;
    const Particles &p = sorted.p;
    const CellSorted::View v = sorted.g.view();
    const double r2 = cell * cell;
    std::size_t packed = 0, coincident = 0, remote = 0, tails = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
        if (v.orig[i] >= v.owned)
            continue;
        for (const auto &[b, e] : ranges_around(v, i)) {
            tails += (e - b) % 8 != 0;
            for (const bool fluid_only : {false, true}) {
                PackedCandidates fast, plain;
                for (auto *pc : {&fast, &plain}) {
                    pc->index.assign(e - b + 8, 0);
                    pc->dx.assign(e - b + 8, 0);
                    pc->dy.assign(e - b + 8, 0);
                }
                pack_in_range(v, v.x[i], v.y[i], r2, fluid_only, b, e, fast);
                pack_in_range_portable(v, v.x[i], v.y[i], r2, fluid_only, b, e, plain);
                // The filter written out.
                std::vector<std::uint32_t> expected;
                std::uint64_t in_range = 0, far = 0;
                for (std::size_t j = b; j < e; ++j) {
                    const double dx = v.x[i] - v.x[j], dy = v.y[i] - v.y[j];
                    const double d2 = dx * dx + dy * dy;
                    if (d2 >= r2 || (fluid_only && v.fluid[j] == 0))
                        continue;
                    ++in_range;
                    far += v.remote[j] > 0;
                    if (d2 > 0)
                        expected.push_back(static_cast<std::uint32_t>(j));
                    else
                        coincident += j != i;
                }
                ASSERT_EQ(fast.size, expected.size()) << i;
                ASSERT_EQ(plain.size, expected.size()) << i;
                for (std::size_t q = 0; q < expected.size(); ++q) {
                    ASSERT_EQ(fast.index[q], expected[q]) << i;
                    ASSERT_EQ(plain.index[q], expected[q]) << i;
                    // Computed in double, stored in the pair terms' precision.
                    const auto dx = static_cast<PairReal>(v.x[i] - v.x[expected[q]]),
                               dy = static_cast<PairReal>(v.y[i] - v.y[expected[q]]);
                    EXPECT_EQ(fast.dx[q], dx);
                    EXPECT_EQ(fast.dy[q], dy);
                    EXPECT_EQ(plain.dx[q], dx);
                    EXPECT_EQ(plain.dy[q], dy);
                }
                EXPECT_EQ(fast.in_range, in_range) << i;
                EXPECT_EQ(plain.in_range, in_range) << i;
                EXPECT_EQ(fast.remote, far) << i;
                EXPECT_EQ(plain.remote, far) << i;
                packed += expected.size();
                remote += far;
            }
        }
    }
    // The cases above all occurred.
    EXPECT_GT(packed, 10000u);
    EXPECT_GT(coincident, 0u);
    EXPECT_GT(remote, 100u);
    EXPECT_GT(tails, 100u);
}

// The passes pack the particles of one cell together (they scan the same ranges): each
// particle's pack is then the one the plain filter gives it alone, positions, separations to
// the bit and counts, for every batch size, with and without wall candidates.
TEST(CellSorted, PackedTogetherIsPackedOneByOne) {
    const PackingCase sorted;
    const Particles &p = sorted.p;
    const CellSorted::View v = sorted.g.view();
    const double r2 = cell * cell;
    std::size_t packed = 0, remote = 0;
    for (int batch = 1; batch <= pack_batch_size; ++batch)
        for (std::size_t i = 0; i + static_cast<std::size_t>(batch) <= p.size(); ++i) {
            // The ranges around sorted position i's cell, for i and the positions after it.
            for (const auto &[b, e] : ranges_around(v, i)) {
                for (const bool fluid_only : {false, true}) {
                    std::vector<PackedCandidates> together(pack_batch_size), alone(pack_batch_size);
                    std::vector<PackedCandidates *> out;
                    std::vector<double> xi, yi;
                    for (int k = 0; k < batch; ++k) {
                        for (auto *pc : {&together[k], &alone[k]}) {
                            pc->index.assign(e - b + 8, 0);
                            pc->dx.assign(e - b + 8, 0);
                            pc->dy.assign(e - b + 8, 0);
                        }
                        out.push_back(&together[k]);
                        xi.push_back(v.x[i + k]);
                        yi.push_back(v.y[i + k]);
                        pack_in_range_portable(v, xi[k], yi[k], r2, fluid_only, b, e, alone[k]);
                    }
                    pack_in_range(v, xi.data(), yi.data(), batch, r2, fluid_only, b, e, out.data());
                    for (int k = 0; k < batch; ++k) {
                        ASSERT_EQ(together[k].size, alone[k].size) << i << " " << k;
                        for (std::size_t q = 0; q < alone[k].size; ++q) {
                            ASSERT_EQ(together[k].index[q], alone[k].index[q]) << i;
                            EXPECT_EQ(together[k].dx[q], alone[k].dx[q]);
                            EXPECT_EQ(together[k].dy[q], alone[k].dy[q]);
                        }
                        EXPECT_EQ(together[k].in_range, alone[k].in_range) << i;
                        EXPECT_EQ(together[k].remote, alone[k].remote) << i;
                        packed += alone[k].size;
                        remote += alone[k].remote;
                    }
                }
            }
        }
    EXPECT_GT(packed, 10000u);
    EXPECT_GT(remote, 100u);
    // A batch outside 1..pack_batch_size is refused, not clamped.
    PackedCandidates one;
    PackedCandidates *out[1] = {&one};
    const double x0 = v.x[0], y0 = v.y[0];
    EXPECT_THROW(pack_in_range(v, &x0, &y0, 0, r2, false, 0, 1, out), std::invalid_argument);
}

// The branch-free kernel the vectorised loops use is the quintic kernel to rounding (the
// compiler may fuse multiply-adds differently in the two, so not always to the last bit).
// A wall particle's density pass skips the candidate ranges that hold no fluid (a dry wall
// packs nothing): the grid's fluid counts per column and row range are the brute-force ones,
// and with water in the western columns only (dry walls to the east, wet walls among
// the water, fluid ghosts in the east column) the density rates are the stored-list drivers'
// to rounding, the dry walls' exactly 0.
TEST(CellSorted, WallsSkipRangesWithoutFluid) {
    Physics phys;
    phys.h = cell / QuinticKernel::support_factor;
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> water_x(3 * cell, 6 * cell), wall_x(3 * cell, 9 * cell),
        y(-cell, 6 * cell), x_east(9 * cell, 10 * cell), u(-1, 1);
    Particles p;
    std::int64_t id = 0;
    for (int i = 0; i < 300; ++i)
        p.add_owned(
            {water_x(rng), y(rng), u(rng), u(rng), 1000 + 10 * u(rng), 0, 1, id++, Kind::fluid});
    // Two walls in the dry east whose one fluid partner sits 0.97 cells above or below, in
    // the last or first row of their range.
    for (const double yf : {2.02 * cell, 3.08 * cell})
        p.add_owned({7.5 * cell, yf, u(rng), u(rng), 1000, 0, 1, id++, Kind::fluid});
    for (int i = 0; i < 400; ++i)
        p.add_owned({wall_x(rng), y(rng), 0, 0, 1000, 0, 1, id++, Kind::boundary});
    for (const double yw : {1.05 * cell, 4.05 * cell})
        p.add_owned({7.5 * cell, yw, 0, 0, 1000, 0, 1, id++, Kind::boundary});
    for (int i = 0; i < 40; ++i)
        p.add_transient({x_east(rng), y(rng), u(rng), u(rng), 1000, 0, 1, id++,
                         i % 2 ? Kind::fluid : Kind::boundary});
    equation_of_state(p, phys);
    Particles q = p;
    CellSorted sorted;
    SortedNeighbours nb;
    sorted.update(q, window);
    const CellSorted::View v = sorted.view();
    for (int c = 0; c < v.cols; ++c)
        for (int r0 = 0; r0 < v.rows; r0 += 3)
            for (int r1 = r0; r1 <= v.rows; r1 += 5) {
                std::uint32_t fluid = 0;
                for (std::uint32_t s = v.start[c * v.rows + r0]; s < v.start[c * v.rows + r1]; ++s)
                    fluid += v.fluid[s] > 0;
                ASSERT_EQ(v.fluid_in(c, r0, r1), fluid)
                    << "column " << c << " rows " << r0 << ".." << r1;
            }
    build_neighbours(sorted, q, window, cell, nb);
    continuity(q, nb, phys, 1e-4);
    CellTable table;
    NeighbourList nl;
    table.update(p, window);
    build_neighbours(table, p, window, cell, nl);
    continuity(p, nl, phys, 1e-4);
    EXPECT_EQ(nb.counts.interactions, nl.counts.interactions);
    EXPECT_EQ(nb.counts.pairs, nl.counts.pairs);
    double scale = 0;
    for (std::size_t i = 0; i < p.owned(); ++i)
        scale = std::max(scale, std::abs(p.drho[i]));
    const auto water_within_support = [&](std::size_t i) {
        for (std::size_t j = 0; j < p.size(); ++j)
            if (p.kind[j] == Kind::fluid && std::hypot(p.x[i] - p.x[j], p.y[i] - p.y[j]) < cell)
                return true;
        return false;
    };
    int dry = 0, wet = 0;
    for (std::size_t i = p.fluid(); i < p.owned(); ++i) {
        EXPECT_NEAR(q.drho[i], p.drho[i], pair_rounding * scale) << i;
        const bool near_water = water_within_support(i);
        if (near_water)
            wet += q.drho[i] != 0;
        else
            EXPECT_EQ(q.drho[i], 0.0) << i;
        dry += !near_water;
    }
    EXPECT_GT(dry, 20);
    EXPECT_GT(wet, 20);
}

TEST(CellSorted, BranchFreeKernelIsTheQuinticKernel) {
    const QuinticKernel k(0.013);
    const BranchFreeKernel b(k);
    const double w_scale = k.value(0), d_scale = std::abs(k.derivative(k.h));
    for (int n = 0; n <= 4000; ++n) {
        const double r = n * 1e-3 * k.h; // 0 .. 4h, whole radii and the support edge included
        EXPECT_NEAR(b.value(r), k.value(r), 1e-14 * w_scale) << r;
        EXPECT_NEAR(b.derivative(r), k.derivative(r), 1e-14 * d_scale) << r;
        if (r >= k.support()) {
            EXPECT_EQ(b.value(r), 0.0) << r; // exactly nothing beyond the support
        }
    }
}

// Particles::permute moves every array together and keeps fluid before walls; CellSorted's
// reorder leaves the owned particles in cell order (walls after fluid) and the grid it then
// builds finds the same pairs.
TEST(CellSorted, ReorderPermutesEveryArrayIntoCellOrder) {
    Particles p = random_configuration(11, 300, 0);
    for (std::size_t i = 0; i < p.size(); ++i) {
        p.vx[i] = 1000.0 + static_cast<double>(p.id[i]); // a field tied to its particle
        p.ax[i] = -static_cast<double>(p.id[i]);
    }
    const PairSet expected = brute_force(p);
    const std::size_t fluid = p.fluid();
    CellSorted g;
    g.reorder(p, window);
    ASSERT_EQ(p.size(), 300u);
    ASSERT_EQ(p.fluid(), fluid);
    std::set<std::int64_t> ids;
    for (std::size_t i = 0; i < p.size(); ++i) {
        ids.insert(p.id[i]);
        EXPECT_EQ(p.vx[i], 1000.0 + static_cast<double>(p.id[i]));
        EXPECT_EQ(p.ax[i], -static_cast<double>(p.id[i]));
        EXPECT_EQ(p.kind[i] == Kind::fluid, i < fluid) << "fluid must stay before walls";
    }
    EXPECT_EQ(ids.size(), 300u);
    // Cell order within each kind: the column never decreases, nor the row within a column.
    auto cell_of = [](const Particles &q, std::size_t i) {
        return std::pair{window.column_of(q.x[i]),
                         static_cast<int>(std::floor(q.y[i] / (cell / CellSorted::rows_per_cell)))};
    };
    for (std::size_t i = 1; i < p.size(); ++i) {
        if (i != fluid) {
            EXPECT_LE(cell_of(p, i - 1), cell_of(p, i)) << "position " << i;
        }
    }
    EXPECT_EQ(search(g, p), expected);
}

// Each thread's block of cells: contiguous, covering every cell, and balanced by candidates
// examined to within one cell's cost; the parallel filing gives the serial sort's order at any
// thread count, on the first update (equal shares of cells) and the next (the last blocks).
TEST(CellSorted, ThreadBlocksAreBalancedAndTheSortIsTheSerialOne) {
    Particles p = random_configuration(5, 900, 120);
    for (std::size_t i = 0; i < p.owned(); i += 2)
        p.x[i] = 3 * cell + 0.3 * (p.x[i] - 3 * cell); // most of the water in the west columns
    const TeamSize team;
    team.set(1);
    CellSorted serial;
    serial.update(p, window);
    const CellSorted::View s = serial.view();
    const std::vector<std::uint32_t> orig(s.orig, s.orig + p.size());
    team.set(3);
    CellSorted g;
    for (int pass = 0; pass < 2; ++pass) {
        g.update(p, window);
        const CellSorted::View v = g.view();
        EXPECT_EQ(std::vector<std::uint32_t>(v.orig, v.orig + p.size()), orig) << "pass " << pass;
        ASSERT_EQ(v.threads, 3);
        const int cells = v.cols * v.rows;
        const std::vector<double> cost = candidates_examined(v);
        const double total = std::accumulate(cost.begin(), cost.end(), 0.0);
        const double largest = *std::max_element(cost.begin(), cost.end());
        EXPECT_EQ(v.blocks[0], 0u);
        EXPECT_EQ(v.blocks[3], static_cast<std::uint32_t>(cells));
        for (int t = 0; t < 3; ++t) {
            ASSERT_LE(v.blocks[t], v.blocks[t + 1]);
            const double block =
                std::accumulate(cost.begin() + v.blocks[t], cost.begin() + v.blocks[t + 1], 0.0);
            EXPECT_NEAR(block, total / 3, largest) << "thread " << t;
        }
    }
}

// The blocks follow the threads' measured speed: a thread that took four times as long as the
// others over an equal block gets a quarter of their share next (1/9, 4/9, 4/9 of the cost);
// a step without timings keeps the shares; another team size starts again from equal ones.
TEST(CellSorted, ThreadBlocksFollowTheThreadsMeasuredSpeed) {
    const Particles p = random_configuration(6, 900, 120);
    const TeamSize team;
    team.set(3);
    CellSorted g;
    const auto block_shares = [&] {
        const CellSorted::View v = g.view();
        const std::vector<double> cost = candidates_examined(v);
        const double total = std::accumulate(cost.begin(), cost.end(), 0.0);
        std::vector<double> shares;
        for (int t = 0; t < v.threads; ++t)
            shares.push_back(
                std::accumulate(cost.begin() + v.blocks[t], cost.begin() + v.blocks[t + 1], 0.0) /
                total);
        return shares;
    };
    g.update(p, window);
    std::vector<double> shares = block_shares();
    ASSERT_EQ(shares.size(), 3u);
    for (int t = 0; t < 3; ++t) {
        const CellSorted::View v = g.view();
        g.add_pass_time(t, (t == 0 ? 4.0 : 1.0) * shares[static_cast<std::size_t>(t)],
                        v.cost[v.blocks[t + 1]] - v.cost[v.blocks[t]]);
    }
    g.update(p, window);
    const std::vector<double> expected{1.0 / 9, 4.0 / 9, 4.0 / 9};
    for (int step = 0; step < 2; ++step) { // the second without timings
        shares = block_shares();
        for (std::size_t t = 0; t < 3; ++t)
            EXPECT_NEAR(shares[t], expected[t], 0.03) << "thread " << t << ", step " << step;
        g.update(p, window);
    }
    team.set(2);
    g.update(p, window);
    shares = block_shares();
    ASSERT_EQ(shares.size(), 2u);
    EXPECT_NEAR(shares[0], 0.5, 0.03);
}

// The pair passes' chunks: a thread takes its own block's front to back, then the other
// blocks' from their back ends; every cell is handed out once, whoever takes it.
TEST(CellSorted, ChunksHandOutEveryCellOnceOwnBlockFirst) {
    const Particles p = random_configuration(7, 900, 120);
    const TeamSize team;
    team.set(3);
    CellSorted g;
    g.update(p, window);
    const CellSorted::View v = g.view();
    ASSERT_EQ(v.threads, 3);
    const auto cells = static_cast<std::uint32_t>(v.cols * v.rows);
    g.start_pass();
    std::vector<int> taken(cells, 0);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> order;
    std::uint32_t c0 = 0, c1 = 0;
    while (g.next_cells(1, c0, c1)) { // thread 1 alone: its block, then the others'
        order.emplace_back(c0, c1);
        for (std::uint32_t c = c0; c < c1; ++c)
            ++taken[c];
    }
    EXPECT_TRUE(std::all_of(taken.begin(), taken.end(), [](int n) { return n == 1; }));
    ASSERT_EQ(order.size(), 3u * CellSorted::chunks_per_block);
    EXPECT_EQ(order.front().first, v.blocks[1]);
    EXPECT_EQ(order[CellSorted::chunks_per_block - 1].second, v.blocks[2]);
    EXPECT_EQ(order[CellSorted::chunks_per_block].second, v.blocks[3]); // thread 2's last
    // Each chunk of a block costs about 1 / chunks_per_block of it (whole cells).
    std::uint64_t largest_cell = 0;
    for (std::uint32_t c = 0; c < cells; ++c)
        largest_cell = std::max(largest_cell, v.cost[c + 1] - v.cost[c]);
    const std::uint64_t block = v.cost[v.blocks[2]] - v.cost[v.blocks[1]];
    for (int k = 0; k < CellSorted::chunks_per_block; ++k) {
        const auto [a, b] = order[static_cast<std::size_t>(k)];
        EXPECT_LE(v.cost[b] - v.cost[a], block / CellSorted::chunks_per_block + largest_cell)
            << "chunk " << k;
    }
    // Concurrently: every cell once over the team.
    g.start_pass();
    std::vector<std::atomic<int>> seen(cells);
#pragma omp parallel
    {
        std::uint32_t a = 0, b = 0;
        while (g.next_cells(omp_get_thread_num(), a, b))
            for (std::uint32_t c = a; c < b; ++c)
                seen[c].fetch_add(1, std::memory_order_relaxed);
    }
    for (std::uint32_t c = 0; c < cells; ++c)
        EXPECT_EQ(seen[c].load(), 1) << "cell " << c;
}

// The sweep's column chunks: a thread alone takes its own block's from the front, then the
// other's from its back end, every column once; chunk k of a block costs 2/5 (3/5)^k of it
// (the last one what is left, (3/5)^7), within one column's cost, so the small ones come last.
TEST(CellSorted, SweepChunksShrinkTowardTheBlocksEnd) {
    const CellWindow wide{cell, 0, 192, -1, 6};
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> x(0, 192 * cell), y(-cell, 6 * cell);
    Particles p;
    for (std::int64_t id = 0; id < 8000; ++id)
        p.add_owned({x(rng), y(rng), 0, 0, 1000, 0, 1, id, Kind::fluid});
    const TeamSize team;
    team.set(2);
    CellSorted g;
    g.update(p, wide);
    const CellSorted::View v = g.view();
    ASSERT_EQ(v.threads, 2);
    const auto rows = static_cast<std::uint32_t>(v.rows);
    const auto cost_at = [&](std::uint32_t col) { return v.cost[col * rows]; };
    std::uint64_t largest_column = 0;
    for (std::uint32_t c = 0; c < static_cast<std::uint32_t>(v.cols); ++c)
        largest_column = std::max(largest_column, cost_at(c + 1) - cost_at(c));
    g.start_sweep();
    std::vector<int> taken(static_cast<std::size_t>(v.cols), 0);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> order;
    std::uint32_t c0 = 0, c1 = 0;
    while (g.next_columns(0, c0, c1)) {
        order.emplace_back(c0, c1);
        for (std::uint32_t c = c0; c < c1; ++c)
            ++taken[c];
    }
    EXPECT_TRUE(std::all_of(taken.begin(), taken.end(), [](int n) { return n == 1; }));
    constexpr int per_block = CellSorted::column_chunks_per_block;
    ASSERT_EQ(order.size(), 2u * per_block);
    EXPECT_EQ(order.front().first, 0u);
    EXPECT_EQ(order[per_block].second, static_cast<std::uint32_t>(v.cols)); // thread 1's last
    const double block =
        static_cast<double>(cost_at(order[per_block - 1].second) - cost_at(order.front().first));
    double share = 0.4;
    for (int k = 0; k < per_block; ++k) {
        const auto [a, b] = order[static_cast<std::size_t>(k)];
        const double expected = k + 1 < per_block ? share : share / 0.4;
        EXPECT_NEAR(static_cast<double>(cost_at(b) - cost_at(a)), expected * block,
                    static_cast<double>(largest_column))
            << "chunk " << k;
        share *= 0.6;
    }
    EXPECT_LT(static_cast<double>(largest_column), 0.03 * block); // a column is a small part
}

TEST(Particles, PermuteRefusesWhatIsNotAFluidFirstPermutation) {
    Particles p = random_configuration(12, 10, 0); // ids 0 and 5 are walls, at positions 8, 9
    std::vector<std::uint32_t> order{1, 0, 2, 3, 4, 5, 6, 7, 8, 9};
    p.permute(order);
    EXPECT_EQ(p.id[0], 2); // fluid ids 1, 2, 3, 4, 6, ... swapped in the first two places
    auto bad = [&](std::vector<std::uint32_t> o) { EXPECT_THROW(p.permute(o), std::logic_error); };
    bad({0, 1, 2, 3, 4, 5, 6, 7, 8});     // too short
    bad({0, 0, 2, 3, 4, 5, 6, 7, 8, 9});  // a particle twice
    bad({0, 1, 2, 3, 4, 5, 6, 8, 7, 9});  // a wall among the fluid
    bad({0, 1, 2, 3, 4, 5, 6, 7, 8, 10}); // beyond the particles
    p.add_transient(p.record(0));
    bad({1, 0, 2, 3, 4, 5, 6, 7, 8, 9}); // transient indices would go stale
}
