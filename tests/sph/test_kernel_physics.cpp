#include "sphperf/sph/config.hpp"
#include "sphperf/sph/gauge.hpp"
#include "sphperf/sph/kernel.hpp"
#include "sphperf/sph/physics.hpp"
#include "sphperf/sph/sorted.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <numbers>

using namespace sphperf::sph;

namespace {
constexpr double delta = 0.01;
const double h = Physics::h_factor * delta * std::sqrt(2.0);
} // namespace

TEST(QuinticKernel, ValuesAtWholeRadii) {
    const QuinticKernel k(h);
    EXPECT_DOUBLE_EQ(k.alpha_d, 7.0 / (478.0 * std::numbers::pi * h * h));
    EXPECT_NEAR(k.value(0), 66 * k.alpha_d, 1e-9 * k.alpha_d); // 3^5 - 6 2^5 + 15
    EXPECT_NEAR(k.value(h), 26 * k.alpha_d, 1e-9 * k.alpha_d); // 2^5 - 6
    EXPECT_NEAR(k.value(2 * h), 1 * k.alpha_d, 1e-9 * k.alpha_d);
    EXPECT_EQ(k.value(3 * h), 0.0);
    EXPECT_EQ(k.value(3.5 * h), 0.0);
    EXPECT_EQ(k.derivative(3 * h), 0.0);
    EXPECT_EQ(k.derivative(0), 0.0); // smooth at the origin
}

TEST(QuinticKernel, DerivativeMatchesFiniteDifferences) {
    const QuinticKernel k(h);
    for (double q : {0.3, 0.99, 1.5, 2.2, 2.9}) {
        const double r = q * h, e = 1e-7 * h;
        EXPECT_NEAR(k.derivative(r), (k.value(r + e) - k.value(r - e)) / (2 * e),
                    1e-5 * std::abs(k.alpha_d / h))
            << "q=" << q;
    }
}

TEST(QuinticKernel, NormalisedOnALattice) {
    // Interior particle of a square lattice with m / rho = delta^2: sum_j V_j W_ij ~ 1.
    const QuinticKernel k(h);
    double sum = 0;
    for (int i = -6; i <= 6; ++i)
        for (int j = -6; j <= 6; ++j)
            sum += delta * delta * k.value(delta * std::hypot(i, j));
    EXPECT_NEAR(sum, 1.0, 1e-3);
}

TEST(PairTerms, PressureForcesAreAntisymmetricAndConserveMomentum) {
    const QuinticKernel k(h);
    const double m = 0.1;
    const PairInput ij{0.006, -0.004, std::hypot(0.006, 0.004), 0.3, -0.2, 1001, 1003, 150, 420, m};
    const PairInput ji{-0.006, 0.004, ij.r, -0.3, 0.2, 1003, 1001, 420, 150, m};
    const auto a = momentum_term(ij, k, 50, 0.1), b = momentum_term(ji, k, 50, 0.1);
    EXPECT_NEAR(a.ax, -b.ax, 1e-12 * std::abs(a.ax)); // equal masses: m a_i = -m a_j
    EXPECT_NEAR(a.ay, -b.ay, 1e-12 * std::abs(a.ay));
    // (v_i - v_j) . grad_i W is symmetric in i and j
    EXPECT_NEAR(continuity_term(ij, k), continuity_term(ji, k),
                1e-12 * std::abs(continuity_term(ij, k)));
    // Repulsive: i is pushed away from j along r_i - r_j.
    EXPECT_GT(a.ax * ij.dx + a.ay * ij.dy, 0);
    // Approaching particles compress: density grows.
    PairInput closing = ij;
    closing.dvx = -ij.dx;
    closing.dvy = -ij.dy;
    EXPECT_GT(continuity_term(closing, k), 0);
}

TEST(PairTerms, ViscosityActsOnlyOnApproachingPairs) {
    const QuinticKernel k(h);
    const PairInput base{0.01, 0, 0.01, 0, 0, 1000, 1000, 0, 0, 0.1};
    PairInput approaching = base, receding = base;
    approaching.dvx = -1; // i moves towards j
    receding.dvx = 1;
    EXPECT_EQ(momentum_term(receding, k, 50, 0.1).ax, 0.0);
    EXPECT_GT(momentum_term(approaching, k, 50, 0.1).ax, 0.0); // braking: pushes i back
    EXPECT_EQ(momentum_term(approaching, k, 50, 0.0).ax, 0.0);
}

TEST(Physics, TaitEquationOfStateRoundTrips) {
    Physics ph;
    EXPECT_EQ(ph.pressure(ph.rho0), 0.0);
    EXPECT_NEAR(ph.density(ph.pressure(1010)), 1010, 1e-9);
    EXPECT_NEAR(ph.tait_b(), 50.0 * 50.0 * 1000 / 7, 1e-9);
}

// gamma = 7 is multiplied out; it must agree with std::pow to rounding, and another exponent
// must still take the general path.
TEST(Physics, TaitPressureMatchesPowForSevenAndOtherExponents) {
    for (const double gamma : {7.0, 5.0, 7.5}) {
        Physics ph;
        ph.gamma = gamma;
        for (const double rho : {940.0, 999.0, 1000.5, 1013.0, 1100.0}) {
            const double want = ph.tait_b() * (std::pow(rho / ph.rho0, gamma) - 1.0);
            EXPECT_NEAR(ph.pressure(rho), want, 1e-13 * ph.tait_b()) << gamma << " " << rho;
            EXPECT_NEAR(ph.density(ph.pressure(rho)), rho, 1e-9) << gamma << " " << rho;
        }
    }
}

TEST(Geometry, ThesisParticleCountsAndRankLimits) {
    Config cfg;
    cfg.physics.h = Physics::h_factor * cfg.physics.delta * std::sqrt(2.0);
    cfg.setup = Setup::dambreak;
    auto g1 = make_geometry(cfg);
    EXPECT_EQ(g1.fluid_particles(), 7381);
    EXPECT_EQ(g1.cell_columns, 81);
    cfg.scale = 2;
    auto g2 = make_geometry(cfg);
    EXPECT_EQ(g2.fluid_particles(), 241 * 121);
    EXPECT_EQ(g2.cell_columns, 162);
    cfg.setup = Setup::still;
    cfg.scale = 1;
    EXPECT_EQ(make_geometry(cfg).fluid_particles(), 19140);
    cfg.scale = 2;
    EXPECT_EQ(make_geometry(cfg).fluid_particles(), 641 * 120);
}

// The speed gauge's data is the same on every call (a fixed LCG), its separations inside the
// support and away from 0, its indices in range; the kernel is the continuity pair term
// m_j W'(r)/r (dv . r) at separations a time step back, summed: equal to a plain loop to rounding.
TEST(SpeedGauge, KernelIsTheContinuityTermOnFixedData) {
    using namespace sphperf::sph;
    const auto d = make_gauge_data(100, 256);
    const auto again = make_gauge_data(100, 256);
    EXPECT_EQ(d.dx, again.dx);
    EXPECT_EQ(d.index, again.index);
    ASSERT_EQ(d.index.size(), 256u);
    for (std::size_t q = 0; q < d.index.size(); ++q) {
        const double r = std::hypot(d.dx[q], d.dy[q]);
        EXPECT_GT(r, 0.29);
        EXPECT_LT(r, 2.86);
        EXPECT_LT(d.index[q], 100u);
    }
    double plain = 0;
    for (std::size_t q = 0; q < 256; ++q) {
        const std::size_t i = (q / 64 * 64) % 100; // each group of 64 pairs is one particle's
        const std::uint32_t j = d.index[q];
        const double dvx = d.vx[i] - d.vx[j], dvy = d.vy[i] - d.vy[j];
        const double mx = d.dx[q] - 1e-4 * dvx, my = d.dy[q] - 1e-4 * dvy;
        const double r = std::hypot(mx, my);
        plain += d.mass[j] * BranchFreeKernel::slope(r) / r * (dvx * mx + dvy * my);
    }
    const double k = gauge_kernel(d.vx, d.vy, d.mass, d.index, d.dx, d.dy);
    EXPECT_NEAR(k, plain, 1e-12 * std::abs(plain));
    EXPECT_NE(k, 0.0);
    // A sample runs it once untimed and `repeats` times timed, on every thread.
    SpeedGauge gauge(256, 3);
    EXPECT_EQ(gauge.pairs_per_sample(), 768u);
    EXPECT_GT(gauge.sample(), 0.0);
    const auto g = make_gauge_data(SpeedGauge::particles, 256);
    const double one = gauge_kernel(g.vx, g.vy, g.mass, g.index, g.dx, g.dy);
    double four = one;
    for (int n = 0; n < 3; ++n)
        four += one;
    EXPECT_DOUBLE_EQ(gauge.checksum(), four);
}

// The core latency gauge reads nothing for one thread and, for a team of two or three, either a
// round trip within its timeout or nothing (the partner descheduled: under ctest -j the tests
// share the cores). What must hold whatever the timing: every sample ends, and a team of one
// never reads.
TEST(CoreLatencyGauge, ReadsARoundTripOrNothingAndAlwaysEnds) {
    const int before = omp_get_max_threads();
    CoreLatencyGauge gauge(3);
    omp_set_num_threads(1);
    EXPECT_TRUE(std::isnan(gauge.sample()));
    for (int team : {2, 3}) {
        omp_set_num_threads(team);
        for (int k = 0; k < 20; ++k) {
            const double rt = gauge.sample();
            EXPECT_TRUE(std::isnan(rt) || (rt > 0 && rt <= CoreLatencyGauge::timeout_s))
                << "team " << team << ", sample " << k << ": " << rt << " s";
        }
    }
    omp_set_num_threads(before);
}
