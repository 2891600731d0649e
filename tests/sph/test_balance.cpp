// Slab cuts (sph/balance.hpp): valid, optimal against brute force, and refusing what cannot be
// cut.
#include "sphperf/sph/balance.hpp"
#include "sphperf/sph/domain.hpp"

#include <gtest/gtest.h>

#include <limits>
#include <random>

using namespace sphperf::sph;

namespace {
// The smallest largest-slab cost over every valid cut, by enumeration.
double brute_force_bottleneck(const std::vector<double> &cost, int ranks) {
    const int columns = static_cast<int>(cost.size());
    double best = std::numeric_limits<double>::infinity();
    std::vector<int> cuts(static_cast<std::size_t>(ranks) + 1);
    cuts.back() = columns;
    // Recursive placement of cuts 1 .. ranks - 1.
    auto place = [&](auto &&self, int r) -> void {
        if (r == ranks) {
            best = std::min(best, max_slab_cost(cost, cuts));
            return;
        }
        for (int c = cuts[static_cast<std::size_t>(r) - 1] + 1; c <= columns - (ranks - r); ++c) {
            cuts[static_cast<std::size_t>(r)] = c;
            self(self, r + 1);
        }
    };
    place(place, 1);
    return best;
}
} // namespace

TEST(Balance, EqualCutsAreTheThesisSlabs) {
    EXPECT_EQ(equal_cuts(3, 7), (std::vector<int>{0, 2, 4, 7}));
    EXPECT_EQ(equal_cuts(1, 5), (std::vector<int>{0, 5}));
    for (int r = 0; r <= 4; ++r)
        EXPECT_EQ(equal_cuts(4, 121)[static_cast<std::size_t>(r)], Slab::first_column(r, 4, 121));
}

TEST(Balance, BalancedCutsAreValidAndOptimal) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(0, 1);
    for (int trial = 0; trial < 300; ++trial) {
        const int columns = 1 + static_cast<int>(rng() % 10);
        const int ranks = 1 + static_cast<int>(rng() % static_cast<unsigned>(columns));
        std::vector<double> cost(static_cast<std::size_t>(columns));
        for (auto &c : cost) // a third of the columns empty, as a dry tank's are
            c = u(rng) < 0.33 ? 0.0 : std::floor(100 * u(rng));
        const auto cuts = balanced_cuts(cost, ranks);
        EXPECT_NO_THROW(check_cuts(cuts, ranks, columns));
        EXPECT_NEAR(max_slab_cost(cost, cuts), brute_force_bottleneck(cost, ranks), 1e-9)
            << "trial " << trial << ": " << columns << " columns, " << ranks << " ranks";
    }
}

TEST(Balance, WaterInTheFirstColumnsGetsMostRanks) {
    // A dam break at t = 0: water in the first 30 of 120 columns, nothing after.
    std::vector<double> cost(120, 0.0);
    for (int c = 0; c < 30; ++c)
        cost[static_cast<std::size_t>(c)] = 60;
    const auto cuts = balanced_cuts(cost, 4);
    EXPECT_EQ(cuts, (std::vector<int>{0, 8, 15, 23, 120})) << "the water split 8/7/8/7 columns";
    EXPECT_NEAR(max_slab_cost(cost, cuts) / (30 * 60 / 4.0), 480.0 / 450.0, 1e-12);
    // Equal slabs leave three ranks without water.
    EXPECT_DOUBLE_EQ(max_slab_cost(cost, equal_cuts(4, 120)), 30 * 60);
}

TEST(Balance, RefusesWhatCannotBeCut) {
    const std::vector<double> three{1, 2, 3};
    EXPECT_THROW(balanced_cuts(three, 4), std::invalid_argument);
    EXPECT_THROW(balanced_cuts(three, 0), std::invalid_argument);
    EXPECT_THROW(balanced_cuts(std::vector<double>{1, -1, 2}, 2), std::invalid_argument);
    EXPECT_THROW(balanced_cuts(std::vector<double>{1, std::nan(""), 2}, 2), std::invalid_argument);
    EXPECT_THROW(check_cuts(std::vector<int>{0, 2, 2, 3}, 3, 3), std::invalid_argument);
    EXPECT_THROW(check_cuts(std::vector<int>{0, 1, 3}, 2, 4), std::invalid_argument);
    EXPECT_THROW(check_cuts(std::vector<int>{0, 3}, 2, 3), std::invalid_argument);
    try {
        check_cuts(std::vector<int>{0, 2, 1, 3}, 3, 3);
    } catch (const std::invalid_argument &e) {
        EXPECT_NE(std::string(e.what()).find("rank 1 would own no column"), std::string::npos)
            << e.what();
    }
}

TEST(Balance, OwnerFollowsTheCuts) {
    Slab s;
    s.ranks = 3;
    s.columns = 10;
    s.cell_size = 0.5;
    s.cuts = {0, 1, 7, 10};
    const int expected[] = {0, 1, 1, 1, 1, 1, 1, 2, 2, 2};
    for (int c = 0; c < 10; ++c)
        EXPECT_EQ(s.owner_of_column(c), expected[c]) << "column " << c;
    EXPECT_EQ(s.owner_of(-1.0), 0); // outside the tank: the edge ranks
    EXPECT_EQ(s.owner_of(99.0), 2);
}
