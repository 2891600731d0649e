#include "sphperf/model/hockney.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <span>

using sphperf::model::fit_line;
using sphperf::model::fit_piecewise;
using sphperf::model::MessageSample;

namespace {
// Sizes 1 B .. 16 MiB, times from a two-piece Hockney model with multiplicative noise.
std::vector<MessageSample> synthetic(double a1, double b1, double a2, double b2, double brk,
                                     double noise, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n(0.0, noise);
    std::vector<MessageSample> s;
    for (double m = 1; m <= 16.0 * (1 << 20); m *= 2) {
        const double t = m <= brk ? a1 + b1 * m : a2 + b2 * m;
        s.push_back({m, t * (1.0 + n(rng))});
    }
    return s;
}
} // namespace

TEST(Hockney, LineRecoversExactParameters) {
    std::vector<MessageSample> s;
    for (double m = 1; m <= 1 << 20; m *= 4)
        s.push_back({m, 2e-6 + 1e-10 * m});
    const auto f = fit_line(s);
    EXPECT_NEAR(f.alpha_s, 2e-6, 1e-15);
    EXPECT_NEAR(f.beta_s_per_byte, 1e-10, 1e-19);
    EXPECT_NEAR(f.r2, 1.0, 1e-12);
    EXPECT_LT(f.max_rel_residual, 1e-9);
}

TEST(Hockney, PiecewiseRecoversBreakpointAndBothPiecesFromNoisyData) {
    // Eager up to 4 KiB: 0.3 us + 0.1 ns/B; rendezvous: 1.5 us + 0.08 ns/B (12.5 GB/s).
    for (unsigned seed = 1; seed <= 5; ++seed) {
        const auto s = synthetic(3e-7, 1e-10, 1.5e-6, 8e-11, 4096, 0.02, seed);
        const auto f = fit_piecewise(s);
        ASSERT_EQ(f.pieces.size(), 2u) << "seed " << seed;
        EXPECT_EQ(f.breakpoint_bytes, 4096) << "seed " << seed;
        EXPECT_NEAR(f.alpha_s(), 3e-7, 0.05 * 3e-7) << "seed " << seed;
        EXPECT_NEAR(f.beta_s_per_byte(), 8e-11, 0.05 * 8e-11) << "seed " << seed;
        EXPECT_NEAR(f.pieces.back().alpha_s, 1.5e-6, 0.5e-6) << "seed " << seed;
        EXPECT_GT(f.r2, 0.99);
        EXPECT_LT(f.max_rel_residual, 0.1);
        // The split model must explain the data better than one line.
        EXPECT_LT(f.max_rel_residual, f.single.max_rel_residual);
    }
}

TEST(Hockney, SmallMessagesAreNotSwampedByLargeOnes) {
    // An unweighted fit would put alpha anywhere within the 16 MiB points' absolute noise
    // (~us); weighting by 1/T^2 keeps the 1-byte latency to a few percent.
    const auto s = synthetic(2e-7, 1e-10, 2e-7, 1e-10, 1e12, 0.01, 11);
    const auto f = fit_line(s);
    EXPECT_NEAR(f.alpha_s, 2e-7, 0.03 * 2e-7);
}

TEST(Hockney, NoBreakOnAStraightLine) {
    const auto s = synthetic(1e-6, 2e-10, 1e-6, 2e-10, 1e12, 0.005, 3);
    const auto f = fit_piecewise(s);
    EXPECT_EQ(f.pieces.size(), 1u);
    EXPECT_EQ(f.breakpoint_bytes, 0);
}

// A split whose small piece fits exactly but with a negative latency (T = 2M - 1 us over 1-8 B,
// as noisy time-shared medians can line up) is not a Hockney model: the fit keeps the latency
// positive rather than taking the split with the least residual.
TEST(Hockney, NoSplitWithANegativeLatency) {
    std::vector<MessageSample> s;
    for (double m = 1; m <= 65536; m *= 2)
        s.push_back({m, 1e-6 * (m <= 8 ? 2 * m - 1 : 40 + 1e-3 * m)});
    ASSERT_LT(fit_line(std::span(s).first(4)).alpha_s, 0); // the best split, unrestricted
    const auto f = fit_piecewise(s);
    EXPECT_GT(f.alpha_s(), 0);
    EXPECT_GT(f.pieces.front().points, 4u);
}

// Nor is a piece whose time falls as messages grow (T = 1 us - 1 ns/B over 1-16 B, as a few noisy
// latency medians can tilt; a 2-rank CI run's small piece once came out at -0.5 ns/B).
TEST(Hockney, NoPieceWhoseTimeFallsWithSize) {
    std::vector<MessageSample> s;
    for (double m = 1; m <= 65536; m *= 2)
        s.push_back({m, m <= 16 ? 1e-6 - 1e-9 * m : 1.2e-6 + 1e-10 * m});
    ASSERT_LT(fit_line(std::span(s).first(5)).beta_s_per_byte, 0); // the best split, unrestricted
    const auto f = fit_piecewise(s);
    for (const auto &p : f.pieces)
        EXPECT_GE(p.beta_s_per_byte, 0) << p.first_bytes << ".." << p.last_bytes << " B";
    EXPECT_GT(f.alpha_s(), 0);
}

TEST(Hockney, RejectsDegenerateInput) {
    EXPECT_THROW(fit_line(std::vector<MessageSample>{{8, 1e-6}}), std::invalid_argument);
    EXPECT_THROW(fit_line(std::vector<MessageSample>{{8, 1e-6}, {8, 2e-6}}), std::invalid_argument);
    EXPECT_THROW(fit_line(std::vector<MessageSample>{{8, 1e-6}, {16, 0}}), std::invalid_argument);
    EXPECT_THROW(fit_piecewise(std::vector<MessageSample>{{16, 1e-6}, {8, 1e-6}}),
                 std::invalid_argument);
}
