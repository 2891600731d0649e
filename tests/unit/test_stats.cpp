#include "sphperf/stats.hpp"

#include <gtest/gtest.h>

#include <random>

TEST(Stats, SummaryAndMedian) {
    const std::vector<double> v{4, 1, 3, 2};
    const auto s = sphperf::summarize(v);
    EXPECT_EQ(s.min, 1);
    EXPECT_EQ(s.max, 4);
    EXPECT_DOUBLE_EQ(s.avg, 2.5);
    EXPECT_DOUBLE_EQ(s.median, 2.5);
    EXPECT_DOUBLE_EQ(sphperf::median(std::vector<double>{5, 1, 3}), 3);
    EXPECT_THROW(sphperf::summarize(std::vector<double>{}), std::invalid_argument);
}

TEST(Stats, MedianConfidenceIntervalCoversTheTrueMedianAboutNinetyFivePercent) {
    std::mt19937 rng(5);
    std::exponential_distribution<double> d(1.0);
    const double true_median = std::log(2.0);
    int covered = 0;
    constexpr int trials = 2000;
    for (int t = 0; t < trials; ++t) {
        std::vector<double> v(60);
        for (auto &x : v)
            x = d(rng);
        const auto ci = sphperf::median_ci95(v);
        covered += ci.lo <= true_median && true_median <= ci.hi;
    }
    EXPECT_GT(covered, 0.93 * trials);
    EXPECT_LT(covered, 0.99 * trials);
}
