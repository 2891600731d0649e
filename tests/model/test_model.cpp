// The runtime model's pure parts: fits against planted coefficients, the slab re-cut, Froude
// rescaling, Hockney piece selection, and validation flagging a planted error.
#include "sphperf/errors.hpp"
#include "sphperf/model/jitter.hpp"
#include "sphperf/model/placement.hpp"
#include "sphperf/model/runtime.hpp"
#include "sphperf/stats.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <numeric>
#include <random>

using namespace sphperf;
using namespace sphperf::model;

TEST(Fit, RecoversPlantedLineAndItsStandardErrors) {
    // y = 3 + 2 x + N(0, 0.5): the estimates land within 4 standard errors, and the standard
    // error of the slope is the textbook sigma / sqrt(Sxx).
    std::mt19937 rng(7);
    std::normal_distribution<double> noise(0.0, 0.5);
    std::vector<double> x, y;
    for (int i = 0; i < 400; ++i) {
        x.push_back(i * 0.05);
        y.push_back(3.0 + 2.0 * x.back() + noise(rng));
    }
    const LinearFit f = fit_line_mr(x, y);
    EXPECT_NEAR(f.coefficient("m"), 2.0, 4 * f.se[0]);
    EXPECT_NEAR(f.coefficient("r"), 3.0, 4 * f.se[1]);
    const double mean = std::accumulate(x.begin(), x.end(), 0.0) / x.size();
    double sxx = 0;
    for (double v : x)
        sxx += (v - mean) * (v - mean);
    EXPECT_NEAR(f.se[0], 0.5 / std::sqrt(sxx), 0.1 * 0.5 / std::sqrt(sxx));
    EXPECT_NEAR(f.rse, 0.5, 0.05);
    EXPECT_GT(f.r2, 0.99);
}

TEST(Fit, RefusesTooFewPointsAndDependentTerms) {
    EXPECT_THROW(fit_line_mr(std::vector<double>{1, 2}, std::vector<double>{1, 2}),
                 std::invalid_argument);
    std::vector<std::vector<double>> X{{1, 2}, {2, 4}, {3, 6}, {4, 8}};
    EXPECT_THROW(fit_linear(X, std::vector<double>{1, 2, 3, 4}, {"a", "b"}), std::invalid_argument);
}

// Robust least squares: a planted line with 1 % noise and a tenth of its points 30 % high (a
// slow spell) is recovered within 0.5 %, the outliers rejected; ordinary least squares on the
// same points is pulled off by more than 1 %.
TEST(Fit, RobustFitRejectsABlockOfOutliers) {
    std::mt19937 rng(5);
    std::normal_distribution<double> noise(0.0, 0.01);
    std::vector<std::vector<double>> X;
    std::vector<double> y;
    for (int i = 0; i < 100; ++i) {
        const double u = i / 99.0;
        X.push_back({1.0, u});
        y.push_back((1.0 + 0.5 * u) * (1 + noise(rng)) * (i >= 20 && i < 30 ? 1.3 : 1.0));
    }
    const RobustFit r = fit_robust(X, y, {"const", "u"});
    EXPECT_NEAR(r.fit.coefficient("const"), 1.0, 0.005);
    EXPECT_NEAR(r.fit.coefficient("u"), 0.5, 0.01);
    ASSERT_EQ(r.weights.size(), y.size());
    for (int i = 20; i < 30; ++i)
        EXPECT_EQ(r.weights[static_cast<std::size_t>(i)], 0.0) << "outlier " << i;
    const LinearFit ls = fit_linear(X, y, {"const", "u"});
    EXPECT_GT(std::abs(ls.coefficient("const") - 1.0), 0.01);
    EXPECT_THROW(fit_robust({{1.0, 0.0}, {1.0, 1.0}}, std::vector<double>{1, 2}, {"const", "u"}),
                 std::invalid_argument);
}

TEST(Fit, CrossValidationPrefersThePlantedTerms) {
    // y depends on x1 and x2; leaving x2 out must score worse held out.
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(0, 10);
    std::normal_distribution<double> noise(0, 0.1);
    std::vector<std::vector<double>> both, one;
    std::vector<double> y;
    std::vector<int> groups;
    for (int i = 0; i < 120; ++i) {
        const double a = u(rng), b = u(rng);
        both.push_back({a, b, 1});
        one.push_back({a, 1});
        y.push_back(1.5 * a + 0.7 * b + 2 + noise(rng));
        groups.push_back(i % 4);
    }
    EXPECT_LT(cross_validate(both, y, groups), 0.2);
    EXPECT_GT(cross_validate(one, y, groups), 5 * cross_validate(both, y, groups));
}

TEST(Fit, RunCrossValidationSeesATermThatOnlyMattersAcrossScales) {
    // Four runs: three small (a per-step constant is a third of their time) and one four times
    // larger. Per point, dropping the constant costs little in seconds next to the large run's
    // noise; per run, it mispredicts the small runs' sums by tens of percent.
    std::mt19937 rng(5);
    std::normal_distribution<double> noise(0, 0.02);
    std::vector<std::vector<double>> with, without;
    std::vector<double> y;
    std::vector<int> groups;
    for (int run = 0; run < 4; ++run) {
        const double size = run == 3 ? 4.0 : 1.0;
        for (int k = 0; k < 30; ++k) {
            const double interactions = size * (80e3 + 2e3 * k);
            with.push_back({interactions, 1.0});
            without.push_back({interactions});
            y.push_back((50e-9 * interactions + 2e-3) * (1 + noise(rng)));
            groups.push_back(run);
        }
    }
    const double good = cross_validate_runs(with, y, groups);
    const double bad = cross_validate_runs(without, y, groups);
    EXPECT_LT(good, 0.03);
    EXPECT_GT(bad, 0.08);
    EXPECT_THROW(cross_validate_runs(with, y, std::vector<int>(y.size(), 0)),
                 std::invalid_argument);
}

// Two setups at one scale, as the main job calibrates: the dam break's interactions cost 1.2x
// the still tank's, both proportional to the work (no per-step constant), and the dam break has
// half the interactions per rank. Pooled, a constant tells the setups apart and soaks up the
// difference (then extrapolates it with the scale); with a level per setup it stays near zero.
struct TwoSetups {
    std::vector<std::vector<double>> with_const, without_const;
    std::vector<double> y;
    std::vector<int> runs, setups;
};
TwoSetups two_setups() {
    std::mt19937 rng(13);
    std::normal_distribution<double> noise(0, 0.02);
    TwoSetups d;
    for (int run = 0; run < 4; ++run) {
        const int setup = run % 2;
        const double level = setup == 0 ? 1.2 : 1.0;
        const double base = setup == 0 ? 80e3 : 160e3;
        for (int k = 0; k < 30; ++k) {
            const double interactions = base * (1 + 0.01 * k); // the flow changes the count a bit
            d.with_const.push_back({interactions, 1.0});
            d.without_const.push_back({interactions});
            d.y.push_back(level * 12e-9 * interactions * (1 + noise(rng)));
            d.runs.push_back(run);
            d.setups.push_back(setup);
        }
    }
    return d;
}

TEST(Fit, LevelledFitRecoversSetupLevelsWithoutAConstant) {
    const TwoSetups d = two_setups();
    const LinearFit pooled = fit_linear(d.with_const, d.y, {"interactions", "const"});
    // Pooled: a constant of the order of the dam break's whole step time.
    EXPECT_GT(pooled.coefficient("const"), 0.3 * 1.2 * 12e-9 * 80e3);
    const LevelledFit lev = fit_levelled(d.with_const, d.y, {"interactions", "const"}, d.setups);
    ASSERT_EQ(lev.levels.size(), 2u);
    EXPECT_NEAR(lev.level(0) / lev.level(1), 1.2, 0.05);
    EXPECT_NEAR((lev.level(0) + lev.level(1)) / 2, 1.0, 1e-9); // normalised to a mean of 1
    EXPECT_LT(std::abs(lev.fit.coefficient("const")), 0.05 * 12e-9 * 80e3);
    EXPECT_EQ(lev.level(7), 1.0); // an unseen setup: the average level
    // Twice the dam break's work is predicted at twice the time, as it would be measured.
    const std::vector<double> x2{160e3, 1.0};
    EXPECT_NEAR(lev.predict(x2, 0), 1.2 * 12e-9 * 160e3, 0.05 * 1.2 * 12e-9 * 160e3);
    // One class, or none: ordinary least squares.
    const LevelledFit one = fit_levelled(d.with_const, d.y, {"interactions", "const"}, {});
    EXPECT_DOUBLE_EQ(one.fit.coefficient("const"), pooled.coefficient("const"));
    EXPECT_THROW(fit_levelled(d.with_const, d.y, {"i", "c"}, std::vector<int>{0, 1}),
                 std::invalid_argument);
}

TEST(Fit, LevelledCrossValidationDoesNotBuyTheConstant) {
    const TwoSetups d = two_setups();
    // Pooled, the constant wins the cross-validation by far ...
    const CvScore pooled_with = cross_validate_score(d.with_const, d.y, d.runs);
    const CvScore pooled_without = cross_validate_score(d.without_const, d.y, d.runs);
    EXPECT_LT(pooled_with.rmse, 0.8 * pooled_without.rmse);
    // ... levelled, the proportional cost is within one standard error of it (the rule keeps
    // the smaller set), and both score at the noise.
    const CvScore with = cross_validate_score(d.with_const, d.y, d.runs, d.setups);
    const CvScore without = cross_validate_score(d.without_const, d.y, d.runs, d.setups);
    EXPECT_LE(without.rmse, with.rmse + with.rmse_se);
    EXPECT_GT(with.rmse_se, 0.0);
    EXPECT_LT(without.rmse, 0.6 * pooled_without.rmse);
    EXPECT_DOUBLE_EQ(cross_validate(d.without_const, d.y, d.runs, d.setups), without.rmse);
}

// The calibration the main job runs at 2 threads: dam breaks at two scales (a 50 us per-step
// cost is a fifth of the small one's step and a twentieth of the large one's) and a still tank
// whose steps are the longest, each run off by a drift of a few percent. In seconds the long
// steps' drift hides the per-step cost; per unit of each run's step it stands out, and the
// relative fit recovers it.
TwoSetups scaled_runs() {
    std::mt19937 rng(17);
    std::normal_distribution<double> noise(0, 0.01);
    constexpr double per_interaction = 5e-9, per_step = 50e-6;
    const std::array<double, 6> drift{1.03, 0.97, 0.98, 1.02, 1.04, 0.96};
    const std::array<double, 6> work{45e3, 45e3, 170e3, 170e3, 800e3, 800e3};
    TwoSetups d;
    for (int run = 0; run < 6; ++run) {
        const int setup = run < 4 ? 0 : 1;
        const double level = setup == 0 ? 1.05 : 0.95;
        for (int k = 0; k < 20; ++k) {
            const double interactions = work[run] * (1 + 0.005 * k);
            d.with_const.push_back({interactions, 1.0});
            d.without_const.push_back({interactions});
            d.y.push_back(level * (per_interaction * interactions + per_step) * drift[run] *
                          (1 + noise(rng)));
            d.runs.push_back(run);
            d.setups.push_back(setup);
        }
    }
    return d;
}

TEST(Fit, RelativeWeightsSeeThePerStepCostOfTheSmallRuns) {
    const TwoSetups d = scaled_runs();
    const std::vector<double> unit = group_median_units(d.y, d.runs);
    std::vector<double> yw = d.y;
    for (std::size_t i = 0; i < yw.size(); ++i)
        yw[i] /= unit[i];
    const auto with = divided_rows(d.with_const, unit),
               without = divided_rows(d.without_const, unit);
    // Per unit of step: the constant beats the proportional cost by more than one standard error.
    const CvScore rel_with = cross_validate_score(with, yw, d.runs, d.setups);
    const CvScore rel_without = cross_validate_score(without, yw, d.runs, d.setups);
    EXPECT_LT(rel_with.rmse + rel_with.rmse_se, rel_without.rmse);
    // In seconds the still tank's drift is as large as the small runs' whole per-step cost: the
    // one-standard-error rule keeps the proportional cost alone.
    const CvScore abs_with = cross_validate_score(d.with_const, d.y, d.runs, d.setups);
    const CvScore abs_without = cross_validate_score(d.without_const, d.y, d.runs, d.setups);
    EXPECT_LE(abs_without.rmse, abs_with.rmse + abs_with.rmse_se);
    // The relative fit recovers both costs (the levels average 1, so a cost is level-scaled).
    const LevelledFit f = fit_levelled(with, yw, {"interactions", "const"}, d.setups);
    const double mean_level = (f.level(0) + f.level(1)) / 2;
    EXPECT_NEAR(f.fit.coefficient("const") * mean_level, 50e-6, 10e-6);
    EXPECT_NEAR(f.fit.coefficient("interactions") * mean_level, 5e-9, 0.25e-9);
    EXPECT_NEAR(f.level(0) / f.level(1), 1.05 / 0.95, 0.03);
}

TEST(Fit, TermRulesPickTheSetTheirDefinitionsSay) {
    const std::vector<CvScore> scores{{1.00, 0.05}, {0.97, 0.04}, {0.99, 0.10}};
    const std::vector<std::size_t> sizes{1, 2, 3};
    EXPECT_EQ(select_term_set(scores, sizes, TermRule::best), 1u);
    EXPECT_EQ(select_term_set(scores, sizes, TermRule::one_se), 0u); // 1.00 <= 0.97 + 0.04
    EXPECT_EQ(select_term_set(scores, sizes, TermRule::one_percent), 1u);
    // Beyond one standard error the larger set stays.
    const std::vector<CvScore> apart{{1.00, 0.01}, {0.97, 0.02}};
    EXPECT_EQ(select_term_set(apart, std::vector<std::size_t>{1, 2}, TermRule::one_se), 1u);
    EXPECT_THROW(select_term_set({}, {}, TermRule::best), std::invalid_argument);
}

// A per-step cost, small beside the calibration runs' drift: runs at two scales, each off by a
// drift of 3 %, and a large run predicted from them. The one-standard-error rule drops the
// constant more often than the best score does, and its proportional cost then carries the
// small runs' share of the constant to the large run, which comes out high on average (session
// 64: the scale-1 dam breaks 3-8 % high over eight main jobs under it).
TEST(Fit, BestScoreKeepsASmallPerStepCostAndExtrapolatesCloser) {
    constexpr double per_interaction = 5e-9, per_step = 20e-6, large = 800e3;
    const std::array<double, 4> work{45e3, 45e3, 170e3, 170e3};
    constexpr int trials = 100;
    double error_best = 0, error_one_se = 0;
    int const_best = 0, const_one_se = 0;
    for (int t = 0; t < trials; ++t) {
        std::mt19937 rng(100 + t);
        std::normal_distribution<double> drift(0, 0.03), noise(0, 0.01);
        std::vector<std::vector<double>> with, without;
        std::vector<double> y;
        std::vector<int> runs;
        for (int run = 0; run < 4; ++run) {
            const double d = 1 + drift(rng);
            for (int k = 0; k < 20; ++k) {
                const double interactions = work[run] * (1 + 0.005 * k);
                with.push_back({interactions, 1.0});
                without.push_back({interactions});
                y.push_back((per_interaction * interactions + per_step) * d * (1 + noise(rng)));
                runs.push_back(run);
            }
        }
        const std::vector<double> unit = group_median_units(y, runs);
        std::vector<double> yw = y;
        for (std::size_t i = 0; i < yw.size(); ++i)
            yw[i] /= unit[i];
        const auto xw_with = divided_rows(with, unit), xw_without = divided_rows(without, unit);
        const std::vector<CvScore> scores{cross_validate_score(xw_without, yw, runs),
                                          cross_validate_score(xw_with, yw, runs)};
        const std::vector<std::size_t> sizes{1, 2};
        const auto predicted = [&](std::size_t set) {
            const std::vector<double> x0{large}, x1{large, 1.0};
            return set == 0 ? fit_linear(xw_without, yw, {"interactions"}).predict(x0)
                            : fit_linear(xw_with, yw, {"interactions", "const"}).predict(x1);
        };
        const double truth = per_interaction * large + per_step;
        const std::size_t best = select_term_set(scores, sizes, TermRule::best),
                          one_se = select_term_set(scores, sizes, TermRule::one_se);
        const_best += best == 1;
        const_one_se += one_se == 1;
        error_best += (predicted(best) / truth - 1) / trials;
        error_one_se += (predicted(one_se) / truth - 1) / trials;
    }
    // Measured with these seeds: the constant kept in 75 and 61 of 100; mean error +0.03 % and
    // +0.67 %.
    EXPECT_GT(const_best, const_one_se);
    EXPECT_GT(error_one_se, 0.004);
    EXPECT_LT(std::abs(error_best), 0.5 * error_one_se);
}

TEST(Fit, GroupMedianUnitsAreEachRunsMedianStep) {
    const std::vector<double> y{1, 3, 2, 10, 30, 20, 0.5};
    const std::vector<int> runs{0, 0, 0, 4, 4, 4, 2};
    const std::vector<double> unit = group_median_units(y, runs);
    EXPECT_EQ(unit, (std::vector<double>{2, 2, 2, 20, 20, 20, 0.5}));
    const auto rows = divided_rows({{4, 1}, {6, 2}}, std::vector<double>{2, 0.5});
    EXPECT_EQ(rows, (std::vector<std::vector<double>>{{2, 0.5}, {12, 4}}));
    EXPECT_THROW(group_median_units(std::vector<double>{0, 0, 1}, std::vector<int>{1, 1, 1}),
                 std::invalid_argument);
    EXPECT_THROW(group_median_units(y, std::vector<int>{0}), std::invalid_argument);
}

TEST(Fit, RunLevelIsTheMedianRunsAndIgnoresOneSlowRun) {
    // Five runs of 60 ns per interaction (2 % noise); one of them measured 35 % slow, with the
    // largest work so it has the leverage. Least squares is pulled up, the median run level is not.
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0, 0.02);
    std::vector<std::vector<double>> X;
    std::vector<double> y;
    std::vector<int> groups;
    for (int run = 0; run < 5; ++run)
        for (int i = 0; i < 30; ++i) {
            const double work = (run == 4 ? 4e5 : 1e5) * (1 + 0.01 * i);
            X.push_back({work});
            y.push_back(60e-9 * work * (run == 4 ? 1.35 : 1.0) * (1 + noise(rng)));
            groups.push_back(run);
        }
    const LinearFit ls = fit_linear(X, y, {"interactions"});
    EXPECT_GT(ls.coef[0], 1.2 * 60e-9);
    const RunLevel level = run_level(ls, X, y, groups);
    ASSERT_EQ(level.factors.size(), 5u);
    const LinearFit f = scaled(ls, level.median);
    EXPECT_NEAR(f.coef[0], 60e-9, 0.02 * 60e-9);
    EXPECT_NEAR(f.se[0] / f.coef[0], ls.se[0] / ls.coef[0], 1e-12);
    EXPECT_NEAR(level.spread_pct, 35, 5);
    // The mean, reported beside, does feel the slow run: four factors near f and one near 1.35 f.
    const double f4 = level.factors[0];
    EXPECT_NEAR(level.mean, (4 * f4 + level.factors[4]) / 5, 0.02 * f4);
    EXPECT_GT(level.mean, level.median);
}

// Session 43's level: three repeats of one configuration, two of them hit by slow spells
// (+12 %, +25 %), and one run of another configuration. The fastest repeat stands for the
// first, and the level is the median over the two configurations; the median over runs is
// pulled up by the spells.
TEST(Fit, FastestRepeatLevelIgnoresSlowSpellsOnRepeats) {
    const std::map<std::string, std::vector<double>> runs = {
        {"dambreak s0.5 2x1", {1.12, 1.00, 1.25}}, {"dambreak s0.7 2x1", {1.04}}};
    EXPECT_NEAR(fastest_repeat_level(runs), 1.02, 1e-12);
    EXPECT_NEAR(sphperf::median(std::vector<double>{1.12, 1.00, 1.25, 1.04}), 1.08, 1e-12);
    EXPECT_NEAR(fastest_repeat_level({{"one run", {0.97}}}), 0.97, 1e-12);
    EXPECT_THROW(fastest_repeat_level({}), std::invalid_argument);
}

// Session 44's band: the scatter of calibration runs about their setup's own level, pooled.
// Planted: a dam break at ln-levels 0.1 +- 0.05 and a still tank at -0.2 +- 0.02 (its lower
// level is the setup's, not scatter), a single run adds no degree of freedom.
TEST(Fit, LevelScatterPoolsEachSetupsDeviations) {
    const std::map<std::string, std::vector<double>> by_setup = {
        {"dambreak", {std::exp(0.15), std::exp(0.05)}},
        {"still", {std::exp(-0.22), std::exp(-0.2), std::exp(-0.18)}},
        {"column", {1.7}}};
    const LevelScatter s = level_scatter(by_setup);
    EXPECT_EQ(s.runs, 6);
    EXPECT_EQ(s.dof, 1 + 2 + 0);
    EXPECT_NEAR(s.sum_sq, 2 * 0.05 * 0.05 + 2 * 0.02 * 0.02, 1e-12);
    EXPECT_NEAR(s.log_sd(), std::sqrt((2 * 0.05 * 0.05 + 2 * 0.02 * 0.02) / 3), 1e-12);
    // Pooling two fits adds sums of squares and degrees of freedom, not standard deviations.
    LevelScatter both = s;
    both += level_scatter({{"dambreak", {1.0, std::exp(0.3)}}});
    EXPECT_EQ(both.dof, 4);
    EXPECT_NEAR(both.log_sd(), std::sqrt((s.sum_sq + 2 * 0.15 * 0.15) / 4), 1e-12);
    // One run per setup: no degree of freedom, no figure.
    EXPECT_EQ(level_scatter({{"dambreak", {1.1}}, {"still", {0.9}}}).log_sd(), 0.0);
    EXPECT_THROW(level_scatter({{"dambreak", {1.0, -1.0}}}), std::invalid_argument);
}

TEST(Workload, RecutFollowsTheAppsSlabsAndEdgeColumns) {
    // 7 columns on 3 ranks: the app's first_column gives [0,2) [2,4) [4,7).
    const std::vector<double> fluid{1, 2, 3, 4, 5, 6, 7}, walls{10, 1, 1, 1, 1, 1, 10};
    const auto s = recut(fluid, walls, 3);
    ASSERT_EQ(s.size(), 3u);
    EXPECT_EQ(s[0].begin, 0);
    EXPECT_EQ(s[1].begin, 2);
    EXPECT_EQ(s[2].begin, 4);
    EXPECT_EQ(s[2].end, 7);
    EXPECT_DOUBLE_EQ(s[0].field, 3);
    EXPECT_DOUBLE_EQ(s[1].field, 7);
    EXPECT_DOUBLE_EQ(s[2].field, 18);
    EXPECT_DOUBLE_EQ(s[2].walls, 12);
    // Rank 1 sends its column 2 west and column 3 east; receives column 1 and column 4.
    EXPECT_DOUBLE_EQ(s[1].export_west, 3 + 1);
    EXPECT_DOUBLE_EQ(s[1].export_east, 4 + 1);
    EXPECT_DOUBLE_EQ(s[1].ghost, (2 + 1) + (5 + 1));
    EXPECT_DOUBLE_EQ(s[0].export_west, 0); // the tank wall has no neighbour
    EXPECT_THROW(recut(fluid, walls, 8), UsageError);
}

TEST(Workload, FroudeRescalingCarriesASyntheticTrace) {
    // Source: scale 1, 10 columns of 1 m, column c holds c particles. Target: scale 2 (tank
    // twice as long), 20 columns of 1 m: target column k covers source [k/2, (k+1)/2), half of
    // source column k/2, so counts come in equal pairs, and the total is the target's own.
    std::vector<double> src(10);
    std::iota(src.begin(), src.end(), 0.0);
    const double total = 4 * 45.0;
    const auto out = rescale_columns(src, 1.0, 10.0, 1.0, 20.0, 20, total);
    ASSERT_EQ(out.size(), 20u);
    EXPECT_NEAR(std::accumulate(out.begin(), out.end(), 0.0), total, 1e-9);
    for (int k = 0; k < 20; ++k)
        EXPECT_NEAR(out[k], 2.0 * (k / 2), 1e-9) << "column " << k;
    // Times scale with sqrt(s): 0.2 s at scale 2 is 0.2 / sqrt(2) s at scale 1.
    EXPECT_NEAR(source_time(0.2, 1.0, 2.0), 0.2 / std::sqrt(2.0), 1e-15);
    EXPECT_NEAR(source_time(0.1, 0.5, 1.0), 0.1 * std::sqrt(0.5), 1e-15);
}

TEST(Workload, TraceInterpolatesAndRefusesToExtrapolate) {
    Trace t;
    t.setup = "dambreak";
    t.times_s = {0.0, 0.1};
    t.columns = {{4, 0}, {2, 2}};
    const auto h = histogram_at(t, 0.05);
    EXPECT_DOUBLE_EQ(h[0], 3);
    EXPECT_DOUBLE_EQ(h[1], 1);
    try {
        histogram_at(t, 0.2);
        FAIL() << "no error for a trace too short";
    } catch (const UsageError &e) {
        EXPECT_NE(std::string(e.what()).find("0.2 s"), std::string::npos) << e.what();
    }
}

TEST(Workload, IdleOnsetIsWhenTheWaterReachesEachSlab) {
    // Water spreading right over 4 columns of 1 m: slab 1 crosses 1 particle half way to
    // t = 0.1 s, slab 2 half way to 0.2 s, slab 3 half way to 0.3 s.
    Trace t;
    t.setup = "dambreak";
    t.scale = 1;
    t.cell_size = 1;
    t.tank_length = 4;
    t.times_s = {0.0, 0.1, 0.2, 0.3};
    t.columns = {{8, 0, 0, 0}, {6, 2, 0, 0}, {4, 2, 2, 0}, {2, 2, 2, 2}};
    Target same;
    same.scale = 1;
    same.cell_size = 1;
    same.tank_length = 4;
    same.columns = 4;
    same.fluid_particles = 8;
    same.wall_columns.assign(4, 0.0);
    const double dt = 0.01;
    auto o = idle_onset(t, same, {0, 1, 2, 3, 4}, dt, 30);
    ASSERT_EQ(o.per_rank.size(), 4u);
    const std::int64_t expected[] = {0, 5, 15, 25};
    for (int r = 0; r < 4; ++r) {
        ASSERT_TRUE(o.per_rank[r]) << "rank " << r;
        EXPECT_NEAR(static_cast<double>(*o.per_rank[r]), expected[r], 1.0) << "rank " << r;
    }
    ASSERT_TRUE(o.all);
    EXPECT_EQ(*o.all, *o.per_rank[3]);
    // Two slabs: the second holds columns 2-3, busy from the water reaching column 2.
    o = idle_onset(t, same, {0, 2, 4}, dt, 30);
    ASSERT_TRUE(o.all);
    EXPECT_NEAR(static_cast<double>(*o.all), 15, 1.0);
    // Not within the steps asked: no onset, and the slabs reached keep theirs.
    o = idle_onset(t, same, {0, 1, 2, 3, 4}, dt, 20);
    EXPECT_FALSE(o.all);
    EXPECT_FALSE(o.per_rank[3]);
    EXPECT_TRUE(o.per_rank[2]);
    // Froude: at scale 4 (lengths x 4, times x 2, 16 columns of 1 m) times double, and counts
    // are rescaled to the target's 128 particles: slab 3 (source column 3) holds 16 x the
    // source count, so it is busy once the source holds 1/16, at 0.2 + 0.1 (1/16) / 2 s,
    // target time 0.40625 s: step 41 (rescaled counts make an early tip: model/NOTES.md).
    Target big = same;
    big.scale = 4;
    big.tank_length = 16;
    big.columns = 16;
    big.fluid_particles = 8 * 16;
    big.wall_columns.assign(16, 0.0);
    o = idle_onset(t, big, {0, 4, 8, 12, 16}, dt, 60);
    ASSERT_TRUE(o.all);
    EXPECT_NEAR(static_cast<double>(*o.all), 41, 1.0);
}

TEST(Workload, DisorderFollowsSimulatedTimeAndAcousticTimeForAnotherSpacing) {
    // Two runs with the same record times: the record is their mean of descents per
    // interaction summed over ranks.
    auto run = [](double d1, double d2) {
        SphRun r;
        r.path = "r.json";
        r.config.delta = 0.01;
        for (auto [t, d] : {std::pair{0.1, d1}, {0.2, d2}}) {
            IntervalStats iv;
            iv.time_s = t;
            RankStats a, b;
            a.interactions = 300;
            a.descents = 300 * d;
            b.interactions = 100;
            b.descents = 100 * d;
            iv.ranks = {a, b};
            r.intervals.push_back(iv);
        }
        return r;
    };
    const Disorder d = disorder_of({run(0.1, 0.3), run(0.2, 0.5)});
    EXPECT_NEAR(d.at(0.1, 0.01), 0.15, 1e-12);
    EXPECT_NEAR(d.at(0.15, 0.01), 0.275, 1e-12);
    EXPECT_NEAR(d.at(0.05, 0.01), 0.15, 1e-12); // before the first record: its value
    // At twice the spacing the acoustic time runs half as fast: 0.3 s there is 0.15 s here.
    EXPECT_NEAR(d.at(0.3, 0.02), 0.275, 1e-12);
    const Disorder back = Disorder::from_json(d.to_json(), "test");
    EXPECT_EQ(back.per_interaction, d.per_interaction);
    try {
        (void)d.at(0.25, 0.01);
        FAIL() << "no error past the record";
    } catch (const UsageError &e) {
        EXPECT_NE(std::string(e.what()).find("needs 0.25 s"), std::string::npos) << e.what();
    }
}

namespace {
// A 2-rank run at scale 0.5 over 8 records (0.01 s apart) of 4 columns of 1000 interactions
// each, rank 0 holding columns 0-1 and rank 1 columns 2-3: the columns' descents at record k are
// column_descents(k), and each rank's compute per interaction is per_interaction(k, D), D the
// descents per interaction of its columns in order_descents(k) (the memory order that sets its
// cost; its own columns' unless another grid's stands for them).
template <class Columns, class Order, class Cost>
SphRun two_rank_column_run(const std::string &path, Columns column_descents, Order order_descents,
                           Cost per_interaction) {
    SphRun r;
    r.path = path;
    r.config.scale = 0.5;
    r.config.cell_size = 0.04;
    r.config.tank_length = 0.16;
    for (int k = 1; k <= 8; ++k) {
        IntervalStats iv;
        iv.time_s = 0.01 * k;
        iv.column_interactions = {1000, 1000, 1000, 1000};
        iv.column_descents = column_descents(k);
        const std::vector<double> order = order_descents(k);
        for (int rank = 0; rank < 2; ++rank) {
            RankStats rk;
            rk.steps = 10;
            rk.field_mean = 100;
            rk.interactions = 2000;
            rk.descents = iv.column_descents[2 * rank] + iv.column_descents[2 * rank + 1];
            const double D = (order[2 * rank] + order[2 * rank + 1]) / 2000;
            rk.timers["comp_s"] = per_interaction(k, D) * rk.steps * rk.interactions;
            iv.ranks.push_back(rk);
        }
        r.intervals.push_back(iv);
    }
    return r;
}
} // namespace

// The wall time no phase timer holds: planted as a run's wall_s beyond its slowest rank's
// timers (rank 1 slower in odd intervals, so the slowest is taken per interval, not per rank),
// recovered per step; the layouts' medians; and the rule predict reads them by.
TEST(Calibrate, UntimedPerStepRecoversTheWallNoTimerHolds) {
    // 8 intervals of 10 steps; both ranks compute 20 ns x 2000 interactions x 10 steps = 0.4 ms
    // an interval; rank 0 waits 1 ms in every interval, rank 1 3 ms in the odd ones. The
    // slowest rank's timers: 3.4 ms in the four odd intervals, 1.4 ms in the four even ones.
    constexpr double timed = 4 * 3.4e-3 + 4 * 1.4e-3, steps = 80;
    auto run = [&](const std::string &path, int ranks, int threads, double untimed_per_step) {
        SphRun r = two_rank_column_run(
            path, [](int) { return std::vector<double>(4, 100.0); },
            [](int) { return std::vector<double>(4, 100.0); }, [](int, double) { return 20e-9; });
        r.config.ranks = ranks;
        r.config.threads = threads;
        for (std::size_t k = 0; k < r.intervals.size(); ++k) {
            r.intervals[k].ranks[0].timers["wait_s"] = 1e-3;
            r.intervals[k].ranks[1].timers["wait_s"] = k % 2 ? 3e-3 : 0.0;
        }
        r.wall_s = timed + untimed_per_step * steps;
        return r;
    };
    EXPECT_NEAR(untimed_s_per_step(run("a", 2, 1, 35e-6)), 35e-6, 1e-15);
    EXPECT_NEAR(untimed_s_per_step(run("none", 2, 1, 0)), 0, 1e-15);
    const nlohmann::json section =
        untimed_per_step({run("a", 2, 1, 30e-6), run("b", 2, 1, 40e-6), run("c", 2, 1, 35e-6),
                          run("d", 1, 1, 5e-6), run("e", 1, 2, 7e-6), run("f", 4, 1, 25e-6)});
    ASSERT_EQ(section.at("layouts").size(), 4u);
    const nlohmann::json &two = section.at("layouts").at(2); // ordered by ranks, then threads
    EXPECT_EQ(two.at("ranks"), 2);
    EXPECT_EQ(two.at("runs"), 3);
    EXPECT_NEAR(two.at("median_s").get<double>(), 35e-6, 1e-15);
    EXPECT_NEAR(two.at("min_s").get<double>(), 30e-6, 1e-15);
    EXPECT_NEAR(two.at("max_s").get<double>(), 40e-6, 1e-15);
    const nlohmann::json model = {{"untimed_per_step", section}};
    EXPECT_NEAR(untimed_s_per_step_for(model, 2, 1), 35e-6, 1e-15);
    EXPECT_NEAR(untimed_s_per_step_for(model, 1, 2), 7e-6, 1e-15);
    // Unseen layouts: the nearest rank count at the same threads (the larger on a tie), else
    // the nearest at any.
    EXPECT_NEAR(untimed_s_per_step_for(model, 3, 1), 25e-6, 1e-15);
    EXPECT_NEAR(untimed_s_per_step_for(model, 8, 1), 25e-6, 1e-15);
    EXPECT_NEAR(untimed_s_per_step_for(model, 2, 2), 7e-6, 1e-15);
    EXPECT_NEAR(untimed_s_per_step_for(model, 2, 4), 35e-6, 1e-15);
    EXPECT_EQ(untimed_s_per_step_for(nlohmann::json::object(), 2, 1), 0.0);
}

// A slow spell of the host inside the one long run (intervals 5 and 6 at 1.4 times the time,
// the speed gauge reading it) bends the cost line fitted within the run; each interval's times
// over its gauge against the run's whole (within_run_speed) recover the planted line's shape.
TEST(Workload, WithinRunSpeedTakesASlowSpellOutOfTheCostLine) {
    constexpr double a = 30e-9, b = 50e-9, spell = 1.4;
    auto descents = [](int k) {
        return std::vector<double>{50.0 + 10 * k, 60.0 + 5 * k, 100.0 + 20 * k, 200.0 + 40 * k};
    };
    SphRun r = two_rank_column_run("spell", descents, descents, [&](int k, double D) {
        return k >= 4 ? (k == 5 || k == 6 ? spell : 1.0) * (a + b * D) : 3 * a;
    });
    for (std::size_t k = 0; k < r.intervals.size(); ++k)
        for (auto &rk : r.intervals[k].ranks) {
            rk.gauge_samples = 10;
            rk.gauge_cpu_s = 10 * 30e-6 * (k == 4 || k == 5 ? spell : 1.0);
        }
    const auto bent = column_disorder_of({r});
    ASSERT_TRUE(bent.has_value());
    EXPECT_GT(std::abs(bent->slope_s / bent->intercept_s / (b / a) - 1), 0.1);
    const auto fixed = column_disorder_of(within_run_speed({r}, 1));
    ASSERT_TRUE(fixed.has_value());
    EXPECT_NEAR(fixed->slope_s / fixed->intercept_s, b / a, 1e-6 * b / a);
    // Without gauge samples the runs stay as they are.
    SphRun bare = r;
    for (auto &iv : bare.intervals)
        for (auto &rk : iv.ranks)
            rk.gauge_samples = rk.gauge_cpu_s = 0;
    const auto kept = within_run_speed({bare}, 1);
    EXPECT_EQ(kept.front().intervals[4].ranks[0].compute_s(),
              bare.intervals[4].ranks[0].compute_s());
}

// A host that speeds up through the one long run (each interval 8 % faster than the one before)
// tilts the cost line fitted within it, as the memory order rises with time too; the run carries
// no gauge samples. Each rank-interval's times over its own kernel's time per interaction
// (within_run_kernel_speed; the kernel, comp_s, planted flat in the order as the search,
// pairs_s, is not) recover the planted line's shape, search plus kernel.
TEST(Workload, WithinRunKernelSpeedTakesAHostDriftOutOfTheCostLine) {
    constexpr double a = 10e-9, b = 60e-9, kernel = 20e-9;
    auto descents = [](int k) {
        return std::vector<double>{50.0 + 10 * k, 60.0 + 5 * k, 100.0 + 20 * k, 200.0 + 40 * k};
    };
    auto host = [](int k) { return std::pow(0.92, k); };
    SphRun r = two_rank_column_run("drift", descents, descents,
                                   [&](int k, double) { return host(k) * kernel; });
    for (std::size_t k = 0; k < r.intervals.size(); ++k)
        for (auto &rk : r.intervals[k].ranks) {
            const double n = rk.steps * rk.interactions;
            rk.timers["pairs_s"] =
                host(static_cast<int>(k) + 1) * (a + b * rk.descents / rk.interactions) * n;
        }
    const auto tilted = column_disorder_of({r});
    ASSERT_TRUE(tilted.has_value());
    const double shape = b / (a + kernel);
    EXPECT_LT(tilted->slope_s / tilted->intercept_s, 0.8 * shape);
    const auto fixed = column_disorder_of(within_run_kernel_speed({r}));
    ASSERT_TRUE(fixed.has_value());
    EXPECT_NEAR(fixed->slope_s / fixed->intercept_s, shape, 1e-6 * shape);
    EXPECT_NEAR(fixed->r2, 1.0, 1e-9);
    // A rank-interval without kernel time stays as it is.
    SphRun bare = r;
    bare.intervals[4].ranks[0].timers.erase("comp_s");
    const auto kept = within_run_kernel_speed({bare});
    EXPECT_EQ(kept.front().intervals[4].ranks[0].compute_s(),
              bare.intervals[4].ranks[0].compute_s());
    EXPECT_NE(kept.front().intervals[4].ranks[1].compute_s(),
              bare.intervals[4].ranks[1].compute_s());
}

TEST(Workload, ColumnDisorderRecoversTheCostLineAndGivesEachSlabItsColumns) {
    // Two rounds (host levels 1 and 1.2) of a 2-rank run over 8 records, 4 columns of 1000
    // interactions each; rank 0 holds columns 0-1, rank 1 columns 2-3. In the later half a
    // rank's compute per interaction is planted as level x (a + b D); in the earlier half it is
    // unrelated to D (the collapse), and the fit must leave it out.
    constexpr double a = 30e-9, b = 50e-9;
    auto descents = [](int k) {
        return std::vector<double>{50.0 + 10 * k, 60.0 + 5 * k, 100.0 + 20 * k, 200.0 + 40 * k};
    };
    auto run = [&](double level) {
        return two_rank_column_run(
            "round" + std::to_string(level), descents, descents, [&](int k, double D) {
                return k >= 4 ? level * (a + b * D) : 3 * a * (k % 2 + 1); // no relation to D
            });
    };
    const auto found = column_disorder_of({run(1.0), run(1.2)});
    ASSERT_TRUE(found.has_value());
    const ColumnDisorder d = ColumnDisorder::from_json(found->to_json(), "test");
    // The levels are normalised to a mean of 1: the line at the mean level, 1.1.
    EXPECT_NEAR(d.intercept_s, 1.1 * a, 1e-6 * a);
    EXPECT_NEAR(d.slope_s, 1.1 * b, 1e-6 * b);
    EXPECT_EQ(d.points, 20u); // 5 later records x 2 ranks x 2 rounds
    auto expected = [&](int k, int begin, int end) {
        const auto dc = descents(k);
        const double all = std::accumulate(dc.begin(), dc.end(), 0.0) / 4000;
        const double own =
            std::accumulate(dc.begin() + begin, dc.begin() + end, 0.0) / (1000.0 * (end - begin));
        return (a + b * own) / (a + b * all);
    };
    const std::vector<int> halves{0, 2, 4};
    auto f = d.rank_factors(0.08, 0.5, 0.04, 0.16, 4, halves);
    ASSERT_EQ(f.size(), 2u);
    EXPECT_NEAR(f[0], expected(8, 0, 2), 1e-9);
    EXPECT_NEAR(f[1], expected(8, 2, 4), 1e-9);
    EXPECT_LT(f[0], 1.0); // the back of the water is the better ordered
    EXPECT_GT(f[1], 1.0);
    // Four slabs of one column each, and a slab without interactions keeps 1.
    f = d.rank_factors(0.05, 0.5, 0.04, 0.16, 4, {0, 1, 2, 3, 4});
    for (int c = 0; c < 4; ++c)
        EXPECT_NEAR(f[static_cast<std::size_t>(c)], expected(5, c, c + 1), 1e-9) << c;
    // Froude similarity: at scale 2 (16 columns) 0.16 s is the record at 0.08 s.
    f = d.rank_factors(0.16, 2.0, 0.04, 0.64, 16, {0, 8, 16});
    EXPECT_NEAR(f[0], expected(8, 0, 2), 1e-9);
    EXPECT_NEAR(f[1], expected(8, 2, 4), 1e-9);
    try {
        (void)d.rank_factors(0.2, 0.5, 0.04, 0.16, 4, halves);
        FAIL() << "no error past the record";
    } catch (const UsageError &e) {
        EXPECT_NE(std::string(e.what()).find("needs 0.2 s"), std::string::npos) << e.what();
    }
    EXPECT_EQ(d.unusable(), "");
    ColumnDisorder flat = d; // Cell+List's descents, a still tank's: a line of noise
    flat.intercept_s = -1e-9;
    EXPECT_NE(flat.unusable().find("intercept"), std::string::npos);
    flat = d;
    flat.slope_se_s = 0.6 * d.slope_s;
    EXPECT_NE(flat.unusable().find("two standard errors"), std::string::npos);
    // Runs without per-column counts (Cell+Sorted, older reports) give none.
    SphRun bare = run(1.0);
    bare.intervals[3].column_interactions.clear();
    EXPECT_FALSE(column_disorder_of({bare}).has_value());
    nlohmann::json j = d.to_json();
    j["column_descents"].erase(0);
    EXPECT_THROW(ColumnDisorder::from_json(j, "test"), UsageError);
}

// Carried to the whole water's order at the target's simulated time, every slab's descents per
// interaction scale by the same ratio, a slab without interactions stays without, and the
// Froude-time order of the whole (the base of factors()) stays: 1 rank's factor is then
// (a + b whole) / (a + b all).
TEST(Workload, SlabsCarriedToTheWholeWatersOrderKeepTheirRatios) {
    ColumnDisorder::SlabOrder o;
    o.slabs = {0.1, std::nullopt, 0.3};
    o.all = 0.2;
    const auto c = ColumnDisorder::at_whole_order(o, 0.3);
    ASSERT_EQ(c.slabs.size(), 3u);
    EXPECT_NEAR(*c.slabs[0], 0.15, 1e-15);
    EXPECT_FALSE(c.slabs[1].has_value());
    EXPECT_NEAR(*c.slabs[2], 0.45, 1e-15);
    EXPECT_EQ(c.all, 0.2);
    ColumnDisorder d;
    d.intercept_s = 30e-9;
    d.slope_s = 50e-9;
    ColumnDisorder::SlabOrder one;
    one.slabs = {0.2};
    one.all = 0.2;
    EXPECT_NEAR(d.factors(ColumnDisorder::at_whole_order(one, 0.3))[0],
                (30e-9 + 50e-9 * 0.3) / (30e-9 + 50e-9 * 0.2), 1e-12);
    // No order to scale (a water without descents): unchanged.
    ColumnDisorder::SlabOrder none;
    none.slabs = {0.0};
    none.all = 0.0;
    EXPECT_EQ(*ColumnDisorder::at_whole_order(none, 0.3).slabs[0], 0.0);
}

TEST(Workload, CellListReadsItsMemoryOrderOffCellTablesColumns) {
    // A Cell+Table run and a Cell+List run of one configuration (2 ranks, 4 columns, 8
    // records). The list's own descents stay at 0.86 per interaction; its rank's compute per
    // interaction is planted as a + b D, D the table's descents per interaction over the rank's
    // equal slab (columns 0-1 and 2-3) at that time, in the later half.
    constexpr double a = 30e-9, b = 40e-9;
    auto table_descents = [](int k) {
        return std::vector<double>{50.0 + 10 * k, 60.0 + 5 * k, 100.0 + 20 * k, 200.0 + 40 * k};
    };
    auto run = [&](const std::string &grid, const std::string &decomposition) {
        SphRun r = two_rank_column_run(
            grid + ".json",
            [&](int k) {
                return grid == "table" ? table_descents(k)
                                       : std::vector<double>{860.0, 860.0, 860.0, 860.0};
            },
            table_descents,
            [&](int k, double D) { return k >= 4 ? a + b * D : 3 * a * (k % 2 + 1); });
        r.config.grid = grid;
        r.config.decomposition = decomposition;
        return r;
    };
    const SphRun table = run("table", "equal"), list = run("list", "equal");
    // Its own descents cannot tell its ranks apart: no line, or one of noise.
    const auto own = column_disorder_of({list});
    EXPECT_TRUE(!own.has_value() || !own->unusable().empty());
    const auto found = column_disorder_of({list}, {table});
    ASSERT_TRUE(found.has_value());
    const ColumnDisorder d = ColumnDisorder::from_json(found->to_json(), "test");
    EXPECT_NEAR(d.intercept_s, a, 1e-6 * a);
    EXPECT_NEAR(d.slope_s, b, 1e-6 * b);
    EXPECT_EQ(d.points, 10u); // 5 later records x 2 ranks
    EXPECT_EQ(d.source, "list.json");
    EXPECT_EQ(d.order_source, "table.json");
    EXPECT_EQ(d.descents[7], table_descents(8)); // the table's columns are carried
    EXPECT_EQ(d.unusable(), "");
    const auto f = d.rank_factors(0.08, 0.5, 0.04, 0.16, 4, {0, 2, 4});
    const auto td = table_descents(8);
    const double all = (td[0] + td[1] + td[2] + td[3]) / 4000;
    EXPECT_NEAR(f[0], (a + b * (td[0] + td[1]) / 2000) / (a + b * all), 1e-9);
    EXPECT_NEAR(f[1], (a + b * (td[2] + td[3]) / 2000) / (a + b * all), 1e-9);
    // Another grid's columns over balanced slabs would be read over the wrong columns.
    EXPECT_FALSE(column_disorder_of({run("list", "balanced")}, {table}).has_value());
    // Runs of other record times cannot lend their columns.
    SphRun shifted = table;
    shifted.intervals[2].time_s += 0.001;
    EXPECT_THROW((void)column_disorder_of({list}, {shifted}), std::invalid_argument);
}

TEST(Workload, PairDensityIsRecordedPerIntervalAndReadAtTheSourceTime) {
    // Two ranks whose pairs per field particle differ; the trace keeps the sum over ranks.
    SphRun r;
    r.path = "r.json";
    r.config.setup = "dambreak";
    r.config.scale = 0.5;
    r.config.cell_size = 0.04;
    r.config.tank_length = 1.61;
    r.initial_columns = {2, 0};
    for (auto [t, per] : {std::pair{0.1, 22.0}, {0.2, 24.0}}) {
        IntervalStats iv;
        iv.time_s = t;
        iv.columns = {1, 1};
        RankStats a, b;
        a.field_mean = 300;
        a.pairs = 300 * (per - 1);
        a.interactions = 2 * a.pairs;
        b.field_mean = 100;
        b.pairs = 100 * (per + 3);
        b.interactions = 2 * b.pairs;
        iv.ranks = {a, b};
        r.intervals.push_back(iv);
    }
    const Trace t = Trace::from_json(trace_of(r).to_json(), "test");
    ASSERT_EQ(t.pairs_per_field.size(), t.times_s.size());
    EXPECT_NEAR(density_at(t, 0.0).pairs, 22.0, 1e-12); // t = 0 holds the first interval's
    EXPECT_NEAR(density_at(t, 0.1).pairs, 22.0, 1e-12);
    EXPECT_NEAR(density_at(t, 0.15).pairs, 23.0, 1e-12);
    EXPECT_NEAR(density_at(t, 0.15).interactions, 46.0, 1e-12);
    // A scale-2 target at 0.3 s is this half-scale trace at 0.15 s (Froude).
    EXPECT_NEAR(density_at(t, source_time(0.3, 0.5, 2.0)).pairs, 23.0, 1e-12);
    EXPECT_THROW((void)density_at(t, 0.25), UsageError);
    nlohmann::json j = trace_of(r).to_json();
    j["pairs_per_field"].erase(0);
    EXPECT_THROW(Trace::from_json(j, "test"), UsageError);
}

TEST(Jitter, ExpectedMaxMatchesClosedForms) {
    const double pi = std::acos(-1.0);
    // Two and three iid normals: mu + sigma / sqrt(pi) and mu + 3 sigma / (2 sqrt(pi)).
    const std::vector<double> m2{5, 5}, s2{0.5, 0.5}, m3{5, 5, 5}, s3{0.5, 0.5, 0.5};
    EXPECT_NEAR(expected_max(m2, s2), 5 + 0.5 / std::sqrt(pi), 1e-9);
    EXPECT_NEAR(expected_max(m3, s3), 5 + 1.5 * 0.5 / std::sqrt(pi), 1e-9);
    // Clark (1961), two normals with different means and spreads.
    const double mu1 = 3, mu2 = 2.5, sd1 = 0.4, sd2 = 0.9;
    const double theta = std::hypot(sd1, sd2), a = (mu1 - mu2) / theta;
    const double Phi = 0.5 * std::erfc(-a / std::sqrt(2.0));
    const double phi = std::exp(-a * a / 2) / std::sqrt(2 * pi);
    const std::vector<double> mc{mu1, mu2}, sc{sd1, sd2};
    EXPECT_NEAR(expected_max(mc, sc), mu1 * Phi + mu2 * (1 - Phi) + theta * phi, 1e-9);
    // A single variable is its mean; a constant far above the noise is the maximum.
    const std::vector<double> one{7}, one_sd{2}, far{1, 100}, far_sd{0.1, 0};
    EXPECT_DOUBLE_EQ(expected_max(one, one_sd), 7);
    EXPECT_DOUBLE_EQ(expected_max(far, far_sd), 100);
    const std::vector<double> bad_sd{-1};
    EXPECT_THROW((void)expected_max(one, bad_sd), std::invalid_argument);
    EXPECT_THROW((void)expected_max(std::vector<double>{}, std::vector<double>{}),
                 std::invalid_argument);
}

namespace {
// The wait of `steps` steps simulated with a planted noise of standard deviation
// jitter_sd(j, compute) on each rank; the blocking exchange makes every rank wait for the slowest.
double simulated_wait(std::mt19937_64 &rng, Jitter j, const std::vector<double> &compute,
                      const std::vector<double> &comm, int steps) {
    std::normal_distribution<double> z;
    double wait = 0;
    for (int s = 0; s < steps; ++s) {
        std::vector<double> t;
        for (std::size_t r = 0; r < compute.size(); ++r)
            t.push_back(compute[r] + jitter_sd(j, compute[r]) * z(rng) + comm[r]);
        const double step = *std::max_element(t.begin(), t.end());
        for (double v : t)
            wait += step - v;
    }
    return wait;
}
} // namespace

TEST(Jitter, FitRecoversAPlantedKFromSimulatedSteps) {
    // Steps simulated with a planted noise on unequal ranks, in either form; the fit must find
    // the planted k again.
    std::mt19937_64 rng(7);
    const std::vector<double> compute{0.010, 0.009, 0.0105}, comm{2e-4, 3e-4, 2e-4};
    constexpr int steps = 40000;
    for (JitterForm form : {JitterForm::sqrt, JitterForm::proportional})
        for (double planted : form == JitterForm::sqrt ? std::vector<double>{0.005, 0.015}
                                                       : std::vector<double>{0.05, 0.15}) {
            const double wait = simulated_wait(rng, {form, planted}, compute, comm, steps);
            const std::vector<BusyInterval> busy{{steps, compute, comm}};
            EXPECT_NEAR(fit_jitter(busy, wait, form), planted, 0.03 * planted)
                << to_string(form) << " " << planted;
        }
    // The square root: four times the compute, twice the standard deviation, half of it
    // relative to the step; proportional: four times.
    EXPECT_DOUBLE_EQ(jitter_sd({JitterForm::sqrt, 0.01}, 0.04),
                     2 * jitter_sd({JitterForm::sqrt, 0.01}, 0.01));
    EXPECT_DOUBLE_EQ(jitter_sd({JitterForm::proportional, 0.1}, 0.04),
                     4 * jitter_sd({JitterForm::proportional, 0.1}, 0.01));
    // Less wait than the ranks' own imbalance gives: no jitter; more than any k gives: the bound.
    const std::vector<BusyInterval> uneven{{100, {0.01, 0.005}, {0, 0}}};
    for (JitterForm form : {JitterForm::sqrt, JitterForm::proportional}) {
        EXPECT_EQ(fit_jitter(uneven, 0.1, form), 0.0);
        EXPECT_EQ(fit_jitter(uneven, 1e6, form), jitter_k_max);
    }
}

TEST(Jitter, CrossValidationPicksThePlantedForm) {
    // Runs of 2 busy ranks whose steps differ 3- and 9-fold (Cell+Sorted's, Cell+Table's and a
    // larger scale's), their waits simulated with one form: predicting each run's wait from the
    // others' median k, the planted form must come out closer, and by a clear margin.
    std::mt19937_64 rng(11);
    const std::vector<double> step_s{0.0018, 0.0020, 0.0052, 0.0050, 0.016, 0.018};
    for (JitterForm planted : {JitterForm::sqrt, JitterForm::proportional}) {
        const Jitter j{planted, planted == JitterForm::sqrt ? 0.01 : 0.08};
        std::vector<WaitRun> runs;
        for (double c : step_s) {
            const std::vector<double> compute{c, 0.98 * c}, comm{1e-5, 1e-5};
            constexpr int steps = 4000;
            WaitRun w;
            w.busy = {{steps, compute, comm}};
            w.measured_wait_s = simulated_wait(rng, j, compute, comm, steps);
            w.measured_time_s = steps * (compute[0] + compute[1] + 2e-5) + w.measured_wait_s;
            runs.push_back(std::move(w));
        }
        const auto score = [&](JitterForm form) {
            std::vector<double> k;
            for (const auto &w : runs)
                k.push_back(fit_jitter(w.busy, w.measured_wait_s, form));
            return jitter_cv_rms(runs, k, form);
        };
        const double right = score(planted);
        const double wrong =
            score(planted == JitterForm::sqrt ? JitterForm::proportional : JitterForm::sqrt);
        EXPECT_LT(2 * right, wrong) << to_string(planted) << ": " << right << " against " << wrong;
    }
    // Two runs leave one other: no median to cross-validate with; one k per run or an error.
    const std::vector<WaitRun> two(2);
    EXPECT_TRUE(std::isnan(jitter_cv_rms(two, std::vector<double>{0.1, 0.1}, JitterForm::sqrt)));
    EXPECT_THROW((void)jitter_cv_rms(two, std::vector<double>{0.1}, JitterForm::sqrt),
                 std::invalid_argument);
}

namespace {
nlohmann::json two_piece_profile() {
    auto piece = [](double a, double b, double lo, double hi) {
        return nlohmann::json{
            {"alpha_s", a}, {"beta_s_per_byte", b}, {"first_bytes", lo}, {"last_bytes", hi}};
    };
    nlohmann::json fit{{"breakpoint_bytes", 2048},
                       {"pieces", {piece(1e-7, 1e-10, 1, 2048), piece(2e-6, 2e-10, 4096, 1e7)}}};
    nlohmann::json slow{{"breakpoint_bytes", 0}, {"pieces", {piece(5e-6, 1e-9, 1, 1e7)}}};
    nlohmann::json pair = fit;
    pair["pus"] = {0, 1};
    pair["locality"] = "same_l3";
    nlohmann::json network{{"breakpoint_bytes", 0}, {"pieces", {piece(5e-5, 1e-9, 1, 1e7)}}};
    return {{"hockney",
             {{"pairs", {pair}},
              {"classes", {{"same_l3", fit}, {"other_package", slow}, {"other_node", network}}}}}};
}
} // namespace

TEST(Placement, RanksGoWhereTheLauncherBindsThem) {
    // Within the cores each rank on its own cores; above them one-thread ranks round-robin,
    // ranks of more threads unbound.
    EXPECT_EQ(launcher_placement(2, 1, 2), (std::vector<int>{0, 1}));
    EXPECT_EQ(launcher_placement(1, 2, 2), (std::vector<int>{0}));
    EXPECT_EQ(launcher_placement(2, 2, 4), (std::vector<int>{0, 2}));
    EXPECT_EQ(launcher_placement(4, 1, 2), (std::vector<int>{0, 1, 0, 1}));
    EXPECT_EQ(launcher_placement(3, 1, 2), (std::vector<int>{0, 1, 0}));
    EXPECT_EQ(launcher_placement(2, 2, 2), (std::vector<int>{-1, -1}));
    EXPECT_THROW(launcher_placement(0, 1, 2), std::invalid_argument);
}

TEST(Placement, TimeSharedStepIsTheBusiestCore) {
    // The 4-rank dam break early on: ranks 0 and 1 hold water, 2 and 3 are idle. Bound
    // round-robin the busy ranks are on different cores: the step is rank 0's compute with its
    // idle core-mate's, and no overhead (its core serves one busy rank).
    const std::vector<double> c{3.0, 1.5, 0.01, 0.02}, field{100, 50, 0, 0};
    const auto bound = time_shared_step(c, field, launcher_placement(4, 1, 2), 1, 2, 1.3);
    EXPECT_DOUBLE_EQ(bound.step_s, 3.01);
    EXPECT_FALSE(bound.shared_core);
    // The still tank on 3 ranks: ranks 0 and 2 share core 0, which sets the step with the
    // overhead; rank 1's core does not. Unbound, the summed compute is spread over both cores.
    const std::vector<double> s{1.0, 1.1, 0.9}, f3{10, 10, 10};
    const auto three = time_shared_step(s, f3, launcher_placement(3, 1, 2), 1, 2, 1.1);
    EXPECT_NEAR(three.step_s, 1.9 * 1.1, 1e-12);
    EXPECT_TRUE(three.shared_core);
    const std::vector<int> unbound(3, -1);
    const auto spread = time_shared_step(s, f3, unbound, 1, 2, 1.1);
    EXPECT_NEAR(spread.step_s, 3.0 / 2 * 1.1, 1e-12);
    EXPECT_TRUE(spread.shared_core);
    // Unbound and one rank slower than the spread demand: the slowest rank, no overhead.
    const auto lone = time_shared_step(c, field, std::vector<int>(4, -1), 1, 2, 1.3);
    EXPECT_DOUBLE_EQ(lone.step_s, 3.0);
    EXPECT_FALSE(lone.shared_core);
    EXPECT_THROW(time_shared_step(s, field, unbound, 1, 2), std::invalid_argument);
}

// The time-shared step replayed (session 39): where the transfers of a parked rank land.
TEST(Placement, ReplayedStepParksTheRankBesideTheBusyOne) {
    // Within the cores, equal work: nobody waits, and the step is one rank's compute.
    const std::array<double, 3> ms{1e-3, 1e-3, 1e-3};
    const auto even = replay_time_shared({ms, ms}, 2, 1.5e-3);
    EXPECT_NEAR(even.step_s, 3e-3, 1e-4);
    for (int r = 0; r < 2; ++r) {
        EXPECT_LT(even.wait_s[static_cast<std::size_t>(r)], 1e-4);
        EXPECT_LT(even.comm_s[static_cast<std::size_t>(r)], 1e-4);
    }
    // The 3-rank dam break early on (session 39's job, ms per step): rank 0 busy on core 0,
    // rank 1 alone on core 1, rank 2 idle beside rank 0. The step is rank 0's compute; rank 1
    // waits for it at the handshakes; rank 2, parked beside it, spends the step in its
    // exchanges, most of it in transfers that wait for rank 1, which waits for rank 0.
    const std::vector<std::array<double, 3>> dam{
        {3.62e-3, 0.04e-3, 8.0e-3}, {0.53e-3, 0.02e-3, 1.61e-3}, {0.01e-3, 0.01e-3, 0.07e-3}};
    const auto three = replay_time_shared(dam, 2, 1.5e-3);
    EXPECT_NEAR(three.step_s, 11.66e-3, 0.02 * 11.66e-3);
    EXPECT_LT(three.wait_s[0] + three.comm_s[0], 0.3e-3);
    EXPECT_NEAR(three.wait_s[1] + three.comm_s[1], three.step_s - 2.16e-3, 0.3e-3);
    EXPECT_LT(three.comm_s[1], 0.3e-3);
    EXPECT_NEAR(three.wait_s[2] + three.comm_s[2], three.step_s - 0.09e-3, 0.3e-3);
    EXPECT_GT(three.comm_s[2], 0.5 * three.step_s);
    // Two busy ranks on one core take turns: the step is their summed compute (to the tick,
    // 5 us, per hand-over) and a little more for the hand-overs.
    const auto shared = replay_time_shared({ms, ms}, 1, 1.5e-3);
    EXPECT_GT(shared.step_s, 0.99 * 6e-3);
    EXPECT_LT(shared.step_s, 1.1 * 6e-3);
    // By exchange: the parked rank's transfers sum to its comm, and the placement given rank
    // by rank is the round-robin one's when it is the same.
    double by_shift = 0;
    for (double x : three.shift_comm_s[2])
        by_shift += x;
    EXPECT_NEAR(by_shift, three.comm_s[2], 1e-12);
    const auto placed = replay_time_shared(dam, std::vector<int>{0, 1, 0}, 1.5e-3);
    EXPECT_EQ(placed.comm_s, three.comm_s);
    EXPECT_EQ(placed.step_s, three.step_s);
    // Ranks 0 and 1 on one core, rank 2 alone: the step is now their summed compute, and rank
    // 1 spends most of it in its exchanges.
    const auto other = replay_time_shared(dam, std::vector<int>{0, 0, 1}, 1.5e-3);
    EXPECT_GT(other.step_s, 0.99 * (11.66e-3 + 2.16e-3));
    EXPECT_GT(other.comm_s[1] + other.wait_s[1], 0.5 * other.step_s);
    EXPECT_THROW(replay_time_shared(dam, std::vector<int>{0, -1, 0}, 1.5e-3),
                 std::invalid_argument);
    EXPECT_THROW(replay_time_shared(dam, std::vector<int>{0, 1}, 1.5e-3), std::invalid_argument);
    EXPECT_THROW(replay_time_shared({}, 2, 1.5e-3), std::invalid_argument);
    EXPECT_THROW(replay_time_shared({ms}, 2, 0.0), std::invalid_argument);
    EXPECT_THROW(replay_time_shared({ms}, 0, 1.5e-3), std::invalid_argument);
}

// How fully every core time-shares two busy ranks (session 80): per core the second busiest
// rank's compute over the busiest's, the least over the cores holding a rank.
TEST(Placement, SharingBubblePhiIsTheLeastSecondOverFirstOfTheCores) {
    const std::vector<int> rr4{0, 1, 0, 1}, rr3{0, 1, 0};
    // Four equal ranks, two per core: 1.
    EXPECT_DOUBLE_EQ(sharing_bubble_phi(std::vector<double>{2, 2, 2, 2}, rr4), 1.0);
    // Core 0: 3 and 2 (2/3); core 1: 4 and 1 (1/4): the least.
    EXPECT_DOUBLE_EQ(sharing_bubble_phi(std::vector<double>{3, 4, 2, 1}, rr4), 0.25);
    // An idle rank beside the busy one (the equal-slab dam break early on): 0.
    EXPECT_DOUBLE_EQ(sharing_bubble_phi(std::vector<double>{5, 3, 0, 1}, rr4), 0.0);
    // Three ranks on two cores: core 1 serves rank 1 alone, whatever the others.
    EXPECT_DOUBLE_EQ(sharing_bubble_phi(std::vector<double>{2, 2, 2}, rr3), 0.0);
    // One core serving three ranks: the second busiest over the busiest.
    EXPECT_DOUBLE_EQ(sharing_bubble_phi(std::vector<double>{4, 1, 2}, std::vector<int>{0, 0, 0}),
                     0.5);
    // No compute anywhere: 0; a negative compute counts as none.
    EXPECT_DOUBLE_EQ(sharing_bubble_phi(std::vector<double>{0, 0, 0, 0}, rr4), 0.0);
    EXPECT_DOUBLE_EQ(sharing_bubble_phi(std::vector<double>{2, 2, -1, 2}, rr4), 0.0);
    EXPECT_THROW(sharing_bubble_phi(std::vector<double>{1, 1}, rr3), std::invalid_argument);
    EXPECT_THROW(sharing_bubble_phi(std::vector<double>{1, 1}, std::vector<int>{0, -1}),
                 std::invalid_argument);
}

TEST(Placement, SharingOverheadLineRecoversPlantedCoefficients) {
    // Planted: 0.1 ms per step plus 12 % of the shared core's compute, runs at 1 ms and 4 ms
    // steps (two each), with +-5 us of noise that cancels pairwise.
    const double a = 1e-4, b = 0.12;
    const std::vector<double> compute{1e-3, 1e-3, 4e-3, 4e-3};
    const std::vector<double> noise{5e-6, -5e-6, -5e-6, 5e-6};
    std::vector<double> overhead;
    for (std::size_t i = 0; i < compute.size(); ++i)
        overhead.push_back(a + b * compute[i] + noise[i]);
    const auto line = fit_sharing_overhead(compute, overhead);
    ASSERT_TRUE(line.has_value());
    EXPECT_NEAR(line->coefficient("const"), a, 1e-12);
    EXPECT_NEAR(line->coefficient("shared_compute"), b, 1e-9);
    // The standard errors of the noise: rse = sqrt(4 x 25e-12 / 2), se(b) = rse / sqrt(Sxx).
    const double rse = std::sqrt(4 * 25e-12 / 2), sxx = 4 * 2.25e-6;
    EXPECT_NEAR(line->rse, rse, 1e-12);
    EXPECT_NEAR(line->se[1], rse / std::sqrt(sxx), 1e-9);
    // One step length (the span below 2x) or fewer than 3 runs: no line, the median is used.
    const std::vector<double> narrow{1e-3, 1.5e-3, 1.9e-3};
    EXPECT_FALSE(fit_sharing_overhead(narrow, std::vector<double>{1e-4, 2e-4, 3e-4}).has_value());
    const std::vector<double> two{1e-3, 4e-3};
    EXPECT_FALSE(fit_sharing_overhead(two, std::vector<double>{1e-4, 5e-4}).has_value());
    EXPECT_THROW(fit_sharing_overhead(two, overhead), std::invalid_argument);
}

TEST(Comm, EachMessageIsCostedWithItsOwnPiece) {
    const CommModel m = CommModel::from_profile(two_piece_profile());
    EXPECT_NEAR(m.seconds(0, 1, 1000), 1e-7 + 1000 * 1e-10, 1e-15);   // small piece
    EXPECT_NEAR(m.seconds(1, 0, 17000), 2e-6 + 17000 * 2e-10, 1e-15); // large piece
    // An unmeasured or unbound placement takes the slowest class within a node, never an
    // optimistic one, nor the network's.
    EXPECT_NEAR(m.seconds(-1, -1, 1000), 5e-6 + 1000 * 1e-9, 1e-15);
    EXPECT_NEAR(m.seconds(0, 7, 1000), 5e-6 + 1000 * 1e-9, 1e-15);
    ASSERT_NE(m.class_named("other_node"), nullptr);
    EXPECT_NEAR(m.class_named("other_node")->fit.predict(1000), 5e-5 + 1000 * 1e-9, 1e-15);
    EXPECT_EQ(m.class_named("same_package"), nullptr);
    // A Sendrecv lasts as long as its longer direction; a missing side costs nothing.
    EXPECT_NEAR(m.sendrecv_seconds(0, 1, 17000, 1, 10), m.seconds(0, 1, 17000), 1e-15);
    EXPECT_NEAR(m.sendrecv_seconds(0, 1, -1, 1, 10), m.seconds(1, 0, 10), 1e-15);
    EXPECT_THROW(CommModel::from_profile(nlohmann::json::object()), UsageError);
}

namespace {
SphRun measured_run(double wall_s) {
    SphRun r;
    r.path = "measured.json";
    r.config = {"dambreak", "table", "fixed", 1, 0.01, 1e-4, 0.04, 3.22, 100, 7381, 1, 1, 100, 81};
    r.wall_s = wall_s;
    IntervalStats iv;
    iv.step = 100;
    iv.time_s = 0.01;
    RankStats rk;
    rk.steps = 100;
    rk.pairs = 1000;
    rk.timers = {{"pairs_s", 0.5}, {"comp_s", 0.5}, {"comm_s", 0}, {"wait_s", 0}};
    iv.ranks = {rk};
    r.intervals = {iv};
    r.peak_rss_bytes = {40e6};
    return r;
}
nlohmann::json prediction(double wall_s) {
    nlohmann::json c{
        {"ranks", 1},
        {"oversubscribed", false},
        {"wall_s", wall_s},
        {"memory", {{"peak_rss_bytes_max_rank", 30e6}, {"thesis_bound_bytes_max_rank", 200e6}}},
        {"totals", {{"compute_s", wall_s}, {"comm_s", 0}, {"wait_s", 0}, {"idle_s", 0}}},
        {"per_rank",
         {{{"pairs_per_step", 1000},
           {"pairs_regression_per_step", 1000},
           {"exported_per_step", 0}}}},
        {"intervals", {{{"ranks", {{{"comm_s", 0}, {"exported_regression", 0}}}}}}}};
    return {{"request",
             {{"setup", "dambreak"},
              {"grid", "table"},
              {"scale", 1},
              {"delta", 0.01},
              {"dt", 1e-4},
              {"steps", 100},
              {"threads", 1}}},
            {"configurations", {c}}};
}
} // namespace

// A planted exchange table: cost = 1 us + 1 us per decade of gap above 1 us + 1 ns per byte,
// overhead 1.2 above the cores. Interpolation must return it between points, hold it outside the
// gaps measured, go on with the last slope above the largest payload, and the rank count must
// be matched by load.
TEST(Comm, ExchangeTableInterpolatesAndMatchesTheLoad) {
    using sphperf::model::ExchangeModel;
    auto planted = [](double gap, double bytes) {
        return 1e-6 + 1e-6 * std::log10(gap / 1e-6) + 1e-9 * bytes;
    };
    auto report = [&](int ranks) {
        nlohmann::json pts = nlohmann::json::array();
        for (double bytes : {64.0, 1024.0})
            for (double gap : {1e-6, 1e-4, 1e-2})
                pts.push_back({{"gap_s_mean", gap},
                               {"payload_bytes", bytes},
                               {"round_overhead", ranks > 2 ? 1.2 : 1.0},
                               {"shift", {{"mean_s", planted(gap, bytes) * ranks / 2}}}});
        return nlohmann::json{{"ranks", ranks}, {"cores", 2}, {"points", pts}};
    };
    const auto m = ExchangeModel::from_profile({{"exchange", {report(2), report(4)}}});
    const auto &two = m.set_for(2, 1, 2);
    EXPECT_EQ(two.ranks, 2);
    EXPECT_EQ(m.set_for(1, 2, 2).ranks, 2); // 1 rank x 2 threads: within the cores
    EXPECT_EQ(m.set_for(3, 1, 2).ranks, 4); // the only oversubscribed set
    EXPECT_EQ(m.set_for(2, 2, 2).ranks, 4); // 2 x 2 on 2 cores is the load of 4 ranks
    for (double gap : {1e-6, 1e-5, 1e-3, 1e-2})
        for (double bytes : {64.0, 300.0, 1024.0})
            EXPECT_NEAR(ExchangeModel::shift_seconds(two, gap, bytes), planted(gap, bytes), 1e-12)
                << gap << " s, " << bytes << " B";
    // Held outside the gaps measured, and below the smallest payload.
    EXPECT_NEAR(ExchangeModel::shift_seconds(two, 1.0, 64), planted(1e-2, 64), 1e-12);
    EXPECT_NEAR(ExchangeModel::shift_seconds(two, 0.0, 8), planted(1e-6, 64), 1e-12);
    EXPECT_NEAR(ExchangeModel::shift_seconds(two, 1e-4, 4096), planted(1e-4, 4096), 1e-12);
    // The app's shifts: the gap since any shift decides (within the cores every message takes
    // the same path; above them a neighbour descheduled since the last exchange). A shift right
    // after another, without a following table, reads the blocking one at its own kind's gap.
    const auto &four = m.set_for(4, 1, 2);
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(two, 3e-3, 1e-2, 64), planted(3e-3, 64), 1e-12);
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(two, 1e-6, 1e-2, 64), planted(1e-2, 64), 1e-12);
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(four, 1e-6, 1e-2, 64),
                ExchangeModel::shift_seconds(four, 1e-6, 64), 1e-12);
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(four, 1e-6, 1e-2, 64), planted(1e-6, 64) * 2,
                1e-12);
    EXPECT_DOUBLE_EQ(ExchangeModel::round_overhead(two, 1e-3), 1.0);
    EXPECT_DOUBLE_EQ(ExchangeModel::round_overhead(m.set_for(4, 1, 2), 1e-3), 1.2);
    EXPECT_TRUE(ExchangeModel::from_profile(nlohmann::json::object()).empty());
    // A malformed section is refused by name.
    auto bad = report(2);
    bad["points"][0]["shift"].erase("mean_s");
    try {
        ExchangeModel::from_profile({{"exchange", {bad}}});
        ADD_FAILURE() << "a point without mean_s was accepted";
    } catch (const sphperf::UsageError &e) {
        EXPECT_NE(std::string(e.what()).find("mean_s"), std::string::npos) << e.what();
    }
}

// A planted blocking shift cost by gap and payload, for the exchange-table tests below.
namespace {
double planted_blocking(double gap, double bytes) {
    return 2e-6 + 1e-6 * gap / 1e-3 + 1e-9 * bytes;
}
} // namespace

// The tables a profile's set keeps (the app costs every shift from them) give what the points
// give when arranged at each call, the way shift_seconds did before session 84: log-linear in
// the gap between a payload's points, linear between payloads, the last slope on past them.
TEST(Comm, AShiftCostsFromTheSetsTablesWhatItsPointsGive) {
    using sphperf::model::ExchangeModel;
    using sphperf::model::ExchangePoint;
    using sphperf::model::ShiftMode;
    std::mt19937 rng(84);
    std::uniform_real_distribution<double> cost(1e-6, 5e-5), unit(0, 1);
    const std::array<double, 3> payloads{16384.0, 64.0, 1024.0}; // unsorted in the report
    const std::array<double, 4> gaps{3e-2, 0.0, 1e-3, 1e-4};
    nlohmann::json pts = nlohmann::json::array();
    for (const char *mode : {"following", "blocking", "overlapped"})
        for (double bytes : payloads)
            for (double gap : gaps)
                pts.push_back({{"gap_s_mean", gap},
                               {"payload_bytes", bytes},
                               {"overlapped", std::string(mode) == "overlapped"},
                               {"follows_shift", std::string(mode) == "following"},
                               {"shift", {{"mean_s", cost(rng)}}}});
    const auto m = ExchangeModel::from_profile(
        {{"exchange", {{{"ranks", 2}, {"cores", 2}, {"points", pts}}}}});
    const auto &set = m.set_for(2, 1, 2);
    ASSERT_TRUE(set.tables);
    // The reference, straight from the points: every point of a payload and mode, by log gap.
    auto reference = [&](double gap, double bytes, ShiftMode mode) {
        auto along = [&](double b) {
            std::vector<std::pair<double, double>> xy;
            for (const ExchangePoint &p : set.points)
                if (p.bytes == b && p.mode == mode)
                    xy.emplace_back(std::log(std::max(p.gap_s, 1e-7)), p.mean_s);
            std::sort(xy.begin(), xy.end());
            const double x = std::log(std::max(gap, 1e-7));
            if (x <= xy.front().first)
                return xy.front().second;
            for (std::size_t i = 1; i < xy.size(); ++i)
                if (x <= xy[i].first)
                    return xy[i - 1].second + (xy[i].second - xy[i - 1].second) *
                                                  (x - xy[i - 1].first) /
                                                  (xy[i].first - xy[i - 1].first);
            return xy.back().second;
        };
        const double b0 = bytes <= 1024 ? 64 : 1024, b1 = bytes <= 1024 ? 1024 : 16384;
        if (bytes <= 64)
            return along(64);
        const double y0 = along(b0), y1 = along(b1);
        return bytes <= b1 ? y0 + (y1 - y0) * (bytes - b0) / (b1 - b0)
                           : y1 + std::max(0.0, (y1 - y0) / (b1 - b0)) * (bytes - b1);
    };
    auto untabled = set;
    untabled.tables.reset();
    for (int k = 0; k < 400; ++k) {
        const double gap = std::exp(std::log(1e-8) + unit(rng) * (std::log(1.0) - std::log(1e-8)));
        const double bytes = 1 + unit(rng) * 40000;
        for (ShiftMode mode : {ShiftMode::blocking, ShiftMode::following, ShiftMode::overlapped}) {
            const double want = reference(gap, bytes, mode);
            EXPECT_NEAR(ExchangeModel::shift_seconds(set, gap, bytes, mode), want, 1e-15 * want)
                << "gap " << gap << " bytes " << bytes;
            EXPECT_EQ(ExchangeModel::shift_seconds(untabled, gap, bytes, mode),
                      ExchangeModel::shift_seconds(set, gap, bytes, mode));
        }
    }
}

// Overlapped points (exchange --overlapped) are a table of their own: each kind interpolates
// among its own points, the round overhead comes from the blocking ones, and a set without
// overlapped points says so.
TEST(Comm, OverlappedExchangePointsAreATableOfTheirOwn) {
    using sphperf::model::ExchangeModel;
    using sphperf::model::ShiftMode;
    auto exposed = [](double gap, double bytes) {
        return 5e-7 + 1e-7 * gap / 1e-3 + 2e-10 * bytes;
    };
    nlohmann::json pts = nlohmann::json::array();
    for (bool ovl : {true, false}) // overlapped first: the order in the report must not matter
        for (double bytes : {64.0, 16384.0})
            for (double gap : {1e-3, 1e-2})
                pts.push_back(
                    {{"gap_s_mean", gap},
                     {"payload_bytes", bytes},
                     {"overlapped", ovl},
                     {"round_overhead", ovl ? 5.0 : 1.5},
                     {"shift",
                      {{"mean_s", ovl ? exposed(gap, bytes) : planted_blocking(gap, bytes)}}}});
    auto without = pts;
    without.erase(without.begin(), without.begin() + 4);
    const auto m = ExchangeModel::from_profile(
        {{"exchange", {{{"ranks", 2}, {"cores", 2}, {"points", pts}}}}});
    const auto &set = m.set_for(2, 1, 2);
    EXPECT_TRUE(set.has(ShiftMode::overlapped));
    // Both tables are linear in the gap and the payload between points; log-linear
    // interpolation in the gap is exact at the points and the payload is linear.
    for (double gap : {1e-3, 1e-2})
        for (double bytes : {64.0, 1000.0, 16384.0}) {
            EXPECT_NEAR(ExchangeModel::shift_seconds(set, gap, bytes), planted_blocking(gap, bytes),
                        1e-12);
            EXPECT_NEAR(ExchangeModel::shift_seconds(set, gap, bytes, ShiftMode::overlapped),
                        exposed(gap, bytes), 1e-12);
        }
    const auto ranks3 = ExchangeModel::from_profile(
        {{"exchange", {{{"ranks", 3}, {"cores", 2}, {"points", pts}}}}});
    EXPECT_NEAR(ExchangeModel::round_overhead(ranks3.sets().front(), 3e-3), 1.5, 1e-12);
    const auto plain = ExchangeModel::from_profile(
        {{"exchange", {{{"ranks", 2}, {"cores", 2}, {"points", without}}}}});
    EXPECT_FALSE(plain.sets().front().has(ShiftMode::overlapped));
    EXPECT_THROW(
        ExchangeModel::shift_seconds(plain.sets().front(), 1e-3, 64, ShiftMode::overlapped),
        std::logic_error);
    // A set the blocking shifts cannot be costed from is refused when read, by name.
    auto only = pts;
    only.erase(only.begin() + 4, only.end());
    try {
        ExchangeModel::from_profile(
            {{"exchange", {{{"ranks", 2}, {"cores", 2}, {"points", only}}}}});
        ADD_FAILURE() << "a set of overlapped points only was accepted";
    } catch (const sphperf::UsageError &e) {
        EXPECT_NE(std::string(e.what()).find("overlapped or following points only"),
                  std::string::npos)
            << e.what();
    }
}

// Following points (exchange --following) cost a shift that comes right after another one, as
// the app's ghosts after its migration: within the cores a shift within a tenth of its step of
// the last one reads them at the gap since its own kind (a set without them: the blocking table
// there); anything else the blocking table at the gap since any shift, as above the cores.
TEST(Comm, FollowingExchangePointsCostAShiftRightAfterAnother) {
    using sphperf::model::ExchangeModel;
    using sphperf::model::ShiftMode;
    auto following = [](double gap, double bytes) {
        return 1e-6 + 3e-7 * gap / 1e-3 + 5e-10 * bytes;
    };
    auto points = [&](bool with_following) {
        nlohmann::json pts = nlohmann::json::array();
        for (bool f : {true, false})
            for (double bytes : {64.0, 16384.0})
                for (double gap : {1e-3, 1e-2})
                    if (!f || with_following)
                        pts.push_back({{"gap_s_mean", gap},
                                       {"payload_bytes", bytes},
                                       {"follows_shift", f},
                                       {"shift",
                                        {{"mean_s", f ? following(gap, bytes)
                                                      : planted_blocking(gap, bytes)}}}});
        return pts;
    };
    auto set = [&](int ranks, bool with_following) {
        return ExchangeModel::from_profile(
                   {{"exchange",
                     {{{"ranks", ranks}, {"cores", 2}, {"points", points(with_following)}}}}})
            .sets()
            .front();
    };
    const auto two = set(2, true);
    EXPECT_TRUE(two.has(ShiftMode::following));
    EXPECT_FALSE(two.has(ShiftMode::overlapped));
    for (double gap : {1e-3, 1e-2})
        for (double bytes : {64.0, 1000.0, 16384.0}) {
            EXPECT_NEAR(ExchangeModel::shift_seconds(two, gap, bytes, ShiftMode::following),
                        following(gap, bytes), 1e-12);
            EXPECT_NEAR(ExchangeModel::shift_seconds(two, gap, bytes), planted_blocking(gap, bytes),
                        1e-12);
        }
    // The ghosts 10 us after the migration of a 10 ms step: following, at the gap since their
    // own kind; the densities half a step after the ghosts: blocking, at the gap since them.
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(two, 1e-5, 1e-2, 16384), following(1e-2, 16384),
                1e-12);
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(two, 1e-2, 2e-2, 16384),
                planted_blocking(1e-2, 16384), 1e-12);
    // Just outside a tenth of the step: blocking, at the gap since any shift.
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(two, 1e-3, 9.9e-3, 64), planted_blocking(1e-3, 64),
                1e-12);
    // The rule before session 32, kept as the untuned comparison: blocking at the gap since the
    // same kind; the ghosts and the time-shared shifts as above.
    using sphperf::model::GapRule;
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(two, 1e-3, 1e-2, 64, GapRule::own_kind_gap),
                planted_blocking(1e-2, 64), 1e-12);
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(two, 1e-5, 1e-2, 16384, GapRule::own_kind_gap),
                following(1e-2, 16384), 1e-12);
    EXPECT_NEAR(
        ExchangeModel::app_shift_seconds(set(3, true), 1e-3, 1e-2, 64, GapRule::own_kind_gap),
        planted_blocking(1e-3, 64), 1e-12);
    // Without following points, the blocking table.
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(set(2, false), 1e-5, 1e-2, 16384),
                planted_blocking(1e-2, 16384), 1e-12);
    // Time-shared: the gap since any shift, blocking (held below the first gap measured).
    EXPECT_NEAR(ExchangeModel::app_shift_seconds(set(3, true), 1e-5, 1e-2, 16384),
                planted_blocking(1e-3, 16384), 1e-12);
    // A point both overlapped and following is refused by name.
    auto both = points(true);
    both[0]["overlapped"] = true;
    try {
        ExchangeModel::from_profile(
            {{"exchange", {{{"ranks", 2}, {"cores", 2}, {"points", both}}}}});
        ADD_FAILURE() << "a point both overlapped and following was accepted";
    } catch (const sphperf::UsageError &e) {
        EXPECT_NE(std::string(e.what()).find("both overlapped and following"), std::string::npos)
            << e.what();
    }
}

TEST(Validate, FlagsAPlantedTwentyPercentError) {
    bool exceeded = false;
    ValidateOptions strict;
    strict.max_error = 0.1;
    auto v = validate({}, {prediction(1.2)}, {measured_run(1.0)}, strict, exceeded);
    EXPECT_TRUE(exceeded);
    ASSERT_EQ(v["configurations"].size(), 1u);
    EXPECT_NEAR(v["configurations"][0]["wall_error"].get<double>(), 0.2, 1e-12);
    EXPECT_NEAR(v["configurations"][0]["phases"]["compute"]["error"].get<double>(), 0.2, 1e-12);
    // Peak RSS: 30 MB predicted against 40 MB measured is -25 %.
    EXPECT_NEAR(v["configurations"][0]["peak_rss_bytes"]["error"].get<double>(), -0.25, 1e-12);
    EXPECT_NEAR(v["summary"]["peak_rss_abs_error"]["max"].get<double>(), 0.25, 1e-12);
    ValidateOptions loose;
    loose.max_error = 0.25;
    validate({}, {prediction(1.2)}, {measured_run(1.0)}, loose, exceeded);
    EXPECT_FALSE(exceeded);
    // A run no prediction covers is listed, not silently dropped.
    auto other = measured_run(1.0);
    other.config.ranks = 5;
    v = validate({}, {prediction(1.2)}, {other}, loose, exceeded);
    EXPECT_EQ(v["unmatched_runs"].size(), 1u);
}

// A 3-rank run (a back rank measured 1 s of compute, a front rank 0.5 s, a dry one 0.01 s; the
// second on core 1, the others sharing core 0) and its prediction, each rank's compute given.
namespace {
struct ThreeRanks {
    SphRun measured;
    nlohmann::json predicted;
};
ThreeRanks three_ranks(std::array<double, 3> predicted_s) {
    ThreeRanks t{measured_run(1.0), prediction(1.0)};
    auto &m = t.measured;
    m.config.ranks = 3;
    RankStats back = m.intervals[0].ranks[0], front = back, dry = back;
    back.timers = {{"comp_s", 1.0}, {"comm_s", 0}, {"wait_s", 0}};
    front.timers = {{"comp_s", 0.5}, {"comm_s", 0}, {"wait_s", 0}};
    dry.timers = {{"comp_s", 0.01}, {"comm_s", 0}, {"wait_s", 0}};
    m.intervals[0].ranks = {back, front, dry};
    m.placement_pus = {0, 1, 0};
    auto &c = t.predicted["configurations"][0];
    c["ranks"] = 3;
    const nlohmann::json one = c["per_rank"][0];
    c["per_rank"] = {one, one, one};
    for (std::size_t r = 0; r < 3; ++r)
        c["per_rank"][r]["compute_s"] = predicted_s[r];
    return t;
}
} // namespace

// Each busy rank's compute apart from their sum (session 56): ranks predicted +10 % and -20 %
// sum to -0.7 %, which the configuration's compute error alone would call right. A rank with
// under a tenth of the compute is listed, not summarised; time-shared runs are summarised apart.
TEST(Validate, ReportsEachBusyRanksComputeApart) {
    auto [m, p] = three_ranks({1.1, 0.4, 0.05});
    auto &c = p["configurations"][0];
    bool exceeded = false;
    auto v = validate({}, {p}, {m}, {}, exceeded);
    ASSERT_EQ(v["configurations"].size(), 1u);
    const auto &ranks = v["configurations"][0]["phases"]["compute"]["per_rank"];
    ASSERT_EQ(ranks.size(), 3u);
    EXPECT_NEAR(ranks[0]["error"].get<double>(), 0.1, 1e-12);
    EXPECT_NEAR(ranks[1]["error"].get<double>(), -0.2, 1e-12);
    EXPECT_FALSE(ranks[2]["busy"].get<bool>());
    const auto &sm = v["summary"]["compute_per_busy_rank_abs_error"];
    EXPECT_EQ(sm["count"], 2);
    EXPECT_NEAR(sm["max"].get<double>(), 0.2, 1e-12);
    EXPECT_TRUE(v["summary"]["compute_per_busy_rank_abs_error_time_shared"].is_null());
    c["oversubscribed"] = true;
    v = validate({}, {p}, {m}, {}, exceeded);
    EXPECT_TRUE(v["summary"]["compute_per_busy_rank_abs_error"].is_null());
    EXPECT_EQ(v["summary"]["compute_per_busy_rank_abs_error_time_shared"]["count"], 2);
}

// Each busy rank's compute at its own core's speed (session 77): the two vCPUs run at different
// speeds in spells, so the run's pooled gauge puts both ranks at one speed. Planted: rank 0 ran
// at 1.2x the reference (its gauge), rank 1 at 0.8x; at their own speeds the predictions are
// -10 % and -20 % off, where the pooled gauge would tell another story for each.
TEST(Validate, ReportsEachBusyRanksComputeAtItsOwnCoresSpeed) {
    auto [m, p] = three_ranks({0.75, 0.5, 0.01});
    constexpr double reference = 3e-5;
    for (auto [r, speed] : {std::pair{0, 1.2}, {1, 0.8}, {2, 1.0}}) {
        auto &rank = m.intervals[0].ranks[static_cast<std::size_t>(r)];
        rank.gauge_cpu_s = 10 * speed * reference;
        rank.gauge_samples = 10;
    }
    auto &c = p["configurations"][0];
    c["speed_gauge_reference_cpu_s"] = reference;
    bool exceeded = false;
    auto v = validate({}, {p}, {m}, {}, exceeded);
    ASSERT_EQ(v["configurations"].size(), 1u);
    const auto &ranks = v["configurations"][0]["phases"]["compute"]["per_rank"];
    ASSERT_EQ(ranks.size(), 3u);
    EXPECT_NEAR(ranks[0]["gauge_factor"].get<double>(), 1.2, 1e-12);
    EXPECT_NEAR(ranks[1]["gauge_factor"].get<double>(), 0.8, 1e-12);
    EXPECT_NEAR(ranks[0]["error_at_own_speed"].get<double>(), -0.1, 1e-12);
    EXPECT_NEAR(ranks[1]["error_at_own_speed"].get<double>(), -0.2, 1e-12);
    // As measured (no gauge) the same ranks read -25 % and 0 %.
    EXPECT_NEAR(ranks[0]["error"].get<double>(), -0.25, 1e-12);
    EXPECT_NEAR(ranks[1]["error"].get<double>(), 0.0, 1e-12);
    // The rank under a tenth of the compute carries its factor but stays out of the summary.
    EXPECT_FALSE(ranks[2]["busy"].get<bool>());
    const auto &sm = v["summary"]["compute_per_busy_rank_at_own_speed"];
    ASSERT_FALSE(sm.is_null());
    EXPECT_EQ(sm["count"], 2);
    EXPECT_NEAR(sm["median_error"].get<double>(), -0.15, 1e-12);
    EXPECT_NEAR(sm["max_abs_error"].get<double>(), 0.2, 1e-12);
    EXPECT_TRUE(v["summary"]["compute_per_busy_rank_at_own_speed_time_shared"].is_null());
    // Time-shared runs are summarised apart; a prediction without a gauge reference gives none.
    c["oversubscribed"] = true;
    v = validate({}, {p}, {m}, {}, exceeded);
    EXPECT_TRUE(v["summary"]["compute_per_busy_rank_at_own_speed"].is_null());
    EXPECT_EQ(v["summary"]["compute_per_busy_rank_at_own_speed_time_shared"]["count"], 2);
    c.erase("speed_gauge_reference_cpu_s");
    v = validate({}, {p}, {m}, {}, exceeded);
    EXPECT_FALSE(
        v["configurations"][0]["phases"]["compute"]["per_rank"][0].contains("error_at_own_speed"));
    EXPECT_TRUE(v["summary"]["compute_per_busy_rank_at_own_speed_time_shared"].is_null());
}

// The memory order each busy rank was predicted at (descents per interaction of its columns)
// and the field particles it was predicted to hold, against the run's: rank 0 predicted 10 %
// high (field 5 % high), rank 1 20 % low (field exact), rank 2 (a few front particles, under a
// tenth of the interactions) left out; a balanced run's memory order apart.
TEST(Validate, ReportsEachBusyRanksMemoryOrderAndWorkloadApart) {
    auto m = measured_run(1.0);
    m.config.ranks = 3;
    RankStats back = m.intervals[0].ranks[0], front = back, dry = back;
    back.interactions = 1000;
    back.descents = 200;
    front.interactions = 1000;
    front.descents = 400;
    dry.interactions = 50;
    dry.descents = 40;
    m.intervals[0].ranks = {back, front, dry};
    auto p = prediction(1.0);
    auto &c = p["configurations"][0];
    c["ranks"] = 3;
    const nlohmann::json one = c["per_rank"][0];
    c["per_rank"] = {one, one, one};
    const nlohmann::json rank = c["intervals"][0]["ranks"][0];
    c["intervals"][0]["ranks"] = {rank, rank, rank};
    for (auto [r, d] : {std::pair{0, 0.22}, {1, 0.32}, {2, 0.9}})
        c["intervals"][0]["ranks"][r]["descents_per_interaction"] = d;
    for (auto [r, field, predicted] :
         {std::tuple{0, 400.0, 420.0}, {1, 300.0, 300.0}, {2, 10.0, 30.0}}) {
        m.intervals[0].ranks[static_cast<std::size_t>(r)].field_mean = field;
        c["intervals"][0]["ranks"][r]["field"] = predicted;
    }
    bool exceeded = false;
    auto v = validate({}, {p}, {m}, {}, exceeded);
    const auto &mo = v["configurations"][0]["memory_order"];
    EXPECT_EQ(mo["count"], 2);
    EXPECT_NEAR(mo["max_abs_error"].get<double>(), 0.2, 1e-12);
    const auto &sm = v["summary"]["descents_per_interaction_per_busy_rank_interval"];
    EXPECT_EQ(sm["count"], 2);
    EXPECT_NEAR(sm["median_error"].get<double>(), -0.05, 1e-12); // (+0.1 - 0.2) / 2
    EXPECT_NEAR(sm["median_abs_error"].get<double>(), 0.15, 1e-12);
    EXPECT_TRUE(v["summary"]["descents_per_interaction_per_busy_rank_interval_balanced"].is_null());
    const auto &wl = v["configurations"][0]["workload"];
    EXPECT_EQ(wl["count"], 2);
    EXPECT_NEAR(wl["max_abs_error"].get<double>(), 0.05, 1e-12);
    EXPECT_NEAR(v["summary"]["field_per_busy_rank_interval"]["median_error"].get<double>(), 0.025,
                1e-12);
    EXPECT_NE(validation_table(v).find("field particles of each busy rank-interval"),
              std::string::npos);
    EXPECT_NE(validation_table(v).find("memory order (descents per interaction)"),
              std::string::npos);
    m.config.decomposition = "balanced";
    p["configurations"][0]["decomposition"] = "balanced";
    v = validate({}, {p}, {m}, {}, exceeded);
    EXPECT_TRUE(v["summary"]["descents_per_interaction_per_busy_rank_interval"].is_null());
    EXPECT_EQ(v["summary"]["descents_per_interaction_per_busy_rank_interval_balanced"]["count"], 2);
    // A prediction without it (Cell+Sorted, --rank-disorder none, Cell+List): nothing.
    for (auto &r : c["intervals"][0]["ranks"])
        r.erase("descents_per_interaction");
    v = validate({}, {p}, {m}, {}, exceeded);
    EXPECT_TRUE(v["configurations"][0]["memory_order"].is_null());
}

// The cost of each busy rank-interval's work apart from the work (session 73): compute per
// interaction, predicted at the run's own host speed over measured, within the cores. Six
// intervals, the run's host 1.25 times slower than the calibration's (its gauge too): the
// prediction's cost per interaction 0 and +2 % off in the first two, +10 % in the middle two,
// +20 and +24 % in the last two (a carry too strong late in the run), and its interactions 10 %
// off throughout, which must not count.
// A time-shared run is left out (its timers hold its core's other rank).
TEST(Validate, ReportsTheCostPerInteractionByThirdsOfTheRun) {
    auto m = measured_run(1.0);
    auto p = prediction(1.0);
    auto &c = p["configurations"][0];
    c["speed_gauge_reference_cpu_s"] = 40e-6;
    const nlohmann::json rank = c["intervals"][0]["ranks"][0];
    const IntervalStats iv = m.intervals[0];
    m.intervals.clear();
    c["intervals"] = nlohmann::json::array();
    for (int k = 0; k < 6; ++k) {
        IntervalStats mk = iv;
        auto &rk = mk.ranks[0];
        rk.steps = 100;
        rk.interactions = 2000 + 100 * k; // per step
        rk.timers = {{"comp_s", 0.02 * (1 + 0.1 * k)}, {"comm_s", 0}, {"wait_s", 0}};
        rk.gauge_cpu_s = 10 * 50e-6; // 1.25 times the reference
        rk.gauge_samples = 10;
        m.intervals.push_back(mk);
        const double measured_cost = rk.compute_s() / (100 * rk.interactions);
        const double planted = std::array{1.0, 1.02, 1.1, 1.1, 1.2, 1.24}[k];
        const double inter = 1.1 * rk.interactions;
        nlohmann::json pr = rank;
        pr["interactions"] = inter;
        // At the reference speed: the run's cost over 1.25, times the planted error.
        pr["compute_s"] = planted * measured_cost / 1.25 * 100 * inter;
        c["intervals"].push_back({{"ranks", {pr}}});
    }
    bool exceeded = false;
    auto v = validate({}, {p}, {m}, {}, exceeded);
    const auto &cp = v["configurations"][0]["cost_per_interaction"];
    ASSERT_FALSE(cp.is_null());
    EXPECT_EQ(cp["count"], 6);
    EXPECT_NEAR(cp["first_third"]["median_error"].get<double>(), 0.01, 1e-12);
    EXPECT_NEAR(cp["last_third"]["median_error"].get<double>(), 0.22, 1e-12);
    EXPECT_NEAR(cp["median_error"].get<double>(), 0.1, 1e-12);
    EXPECT_NEAR(cp["max_abs_error"].get<double>(), 0.24, 1e-12);
    const auto &sm = v["summary"];
    EXPECT_EQ(sm["cost_per_interaction_per_busy_rank_interval"]["count"], 6);
    EXPECT_NEAR(
        sm["cost_per_interaction_per_busy_rank_interval_last_third"]["median_error"].get<double>(),
        0.22, 1e-12);
    EXPECT_NE(validation_table(v).find("cost per interaction of each busy rank-interval"),
              std::string::npos);
    // Without the gauge there is no own speed to price the run at: nothing reported.
    for (auto &i : m.intervals)
        i.ranks[0].gauge_samples = 0;
    v = validate({}, {p}, {m}, {}, exceeded);
    EXPECT_TRUE(v["configurations"][0]["cost_per_interaction"].is_null());
    EXPECT_TRUE(v["summary"]["cost_per_interaction_per_busy_rank_interval"].is_null());
    for (auto &i : m.intervals)
        i.ranks[0].gauge_samples = 10;
    c["oversubscribed"] = true;
    v = validate({}, {p}, {m}, {}, exceeded);
    EXPECT_TRUE(v["summary"]["cost_per_interaction_per_busy_rank_interval"].is_null());
}

// The speed gauge (session 50): a run measured on a host 1.3 times slower, its gauge 1.3 times
// slower too, is predicted 20 % high at the reference speed and 1.2 x 1.3 - 1 = +56 % high at its
// own speed. The band stays the prediction's; a run without gauge samples, or a prediction
// without a reference, gets no correction.
TEST(Validate, ReportsTheErrorAtTheRunsOwnHostSpeed) {
    auto p = prediction(1.2);
    p["configurations"][0]["speed_gauge_reference_cpu_s"] = 50e-6;
    p["configurations"][0]["wall_band"] = {
        {"log_sd", 0.05}, {"dof", 10}, {"sds", 2}, {"low_s", 1.0}, {"high_s", 1.4}};
    auto slow = measured_run(1.0);
    slow.intervals[0].ranks[0].gauge_cpu_s = 10 * 65e-6;
    slow.intervals[0].ranks[0].gauge_samples = 10;
    bool exceeded = false;
    auto v = validate({}, {p}, {slow}, {}, exceeded);
    const auto &c = v["configurations"][0];
    EXPECT_NEAR(c["wall_error"].get<double>(), 0.2, 1e-12); // the prediction's own error
    EXPECT_NEAR(c["speed_gauge"]["factor"].get<double>(), 1.3, 1e-12);
    EXPECT_NEAR(c["speed_gauge"]["wall_error"].get<double>(), 1.2 * 1.3 - 1, 1e-12);
    EXPECT_NEAR(c["wall_band"]["z"].get<double>(), std::log(1.0 / 1.2) / 0.05, 1e-9);
    EXPECT_NEAR(v["summary"]["wall_abs_error_speed_corrected"]["max"].get<double>(), 1.2 * 1.3 - 1,
                1e-12);
    EXPECT_NEAR(v["summary"]["speed_factor"]["median"].get<double>(), 1.3, 1e-12);
    // No samples in the run: no correction, and the band at the prediction itself.
    v = validate({}, {p}, {measured_run(1.0)}, {}, exceeded);
    EXPECT_TRUE(v["configurations"][0]["speed_gauge"].is_null());
    EXPECT_TRUE(v["summary"]["wall_abs_error_speed_corrected"].is_null());
    EXPECT_NEAR(v["configurations"][0]["wall_band"]["z"].get<double>(), std::log(1.0 / 1.2) / 0.05,
                1e-9);
    // No reference in the prediction (a model calibrated with --speed-gauge off): none either.
    v = validate({}, {prediction(1.2)}, {slow}, {}, exceeded);
    EXPECT_TRUE(v["configurations"][0]["speed_gauge"].is_null());
}

// Calibration runs at one host speed: two runs of the same work, one on a host 1.5 times
// slower (every time it measured and its gauge 1.5 times the other's), come out equal at the
// median run's speed; what the runs predicted (comm_predict_s) is left alone. A run without
// gauge samples, or --speed-gauge off, leaves every run as measured and says why.
TEST(Calibrate, SpeedGaugePutsTheRunsAtOneHostSpeed) {
    auto run = [](double slow) {
        SphRun r = measured_run(2.0 * slow);
        auto &rk = r.intervals[0].ranks[0];
        for (auto &[k, v] : rk.timers)
            v = (k == "comm_s" ? 0.1 : 0.5) * slow;
        rk.idle_s = 0.2 * slow;
        rk.shift_comm_s = {0.01 * slow, 0.02 * slow, 0.03 * slow};
        rk.comm_predict_s = 0.05;
        rk.gauge_cpu_s = 20 * 40e-6 * slow;
        rk.gauge_samples = 20;
        return r;
    };
    std::vector<SphRun> runs{run(1.0), run(1.5), run(1.5)};
    const auto j = speed_normalise(runs, SpeedGauge::run);
    ASSERT_TRUE(j["applied"].get<bool>());
    EXPECT_NEAR(j["reference_cpu_s_per_sample"].get<double>(), 60e-6, 1e-15);
    EXPECT_NEAR(j["runs"][0]["factor"].get<double>(), 1 / 1.5, 1e-12);
    for (const auto &r : runs) {
        EXPECT_NEAR(r.wall_s, 3.0, 1e-12);
        const auto &rk = r.intervals[0].ranks[0];
        EXPECT_NEAR(rk.timer("pairs_s"), 0.75, 1e-12);
        EXPECT_NEAR(rk.timer("comm_s"), 0.15, 1e-12);
        EXPECT_NEAR(rk.idle_s, 0.3, 1e-12);
        EXPECT_NEAR(rk.shift_comm_s[2], 0.045, 1e-12);
        EXPECT_NEAR(r.gauge_per_sample_s(), 60e-6, 1e-15);
        EXPECT_DOUBLE_EQ(rk.comm_predict_s, 0.05);
    }
    EXPECT_GT(j["log_sd"].get<double>(), 0.2);
    // A rank that computes nothing (a dam break's far slab) does not set the run's speed.
    SphRun two = run(1.0);
    RankStats idle = two.intervals[0].ranks[0];
    for (auto &[k, v] : idle.timers)
        v = 0;
    idle.gauge_cpu_s *= 3;
    two.intervals[0].ranks.push_back(idle);
    EXPECT_NEAR(two.gauge_per_sample_s(), 40e-6, 1e-15);
    std::vector<SphRun> mixed{run(1.0), measured_run(2.0)};
    const auto none = speed_normalise(mixed, SpeedGauge::interval);
    EXPECT_FALSE(none["applied"].get<bool>());
    EXPECT_NE(none["reason"].get<std::string>().find("measured.json"), std::string::npos);
    EXPECT_DOUBLE_EQ(mixed[0].wall_s, 2.0);
    std::vector<SphRun> off{run(1.0), run(1.5)};
    EXPECT_FALSE(speed_normalise(off, SpeedGauge::off)["applied"].get<bool>());
    EXPECT_DOUBLE_EQ(off[1].wall_s, 3.0);
}

// The elasticity of the compute to the gauge, recovered from synthetic runs: each busy
// rank-interval's compute per interaction is its rank's level, times a trend through the run,
// times the interval's gauge (over a reference) raised to a planted 0.5, times a small noise;
// the gauge wanders in spells as this VM's does. A run above the cores (its timers hold the
// time it waited for a core) follows the gauge whole and stays out. fitted then divides each
// interval's times by its factor raised to the estimate; one by the factor itself.
TEST(Calibrate, GaugeElasticityIsRecoveredAndAppliedWhenFitted) {
    constexpr double planted = 0.5;
    std::mt19937 rng(7);
    std::normal_distribution<double> noise(0, 0.01);
    std::uniform_real_distribution<double> spell(0, 1);
    auto make = [&](int ranks, double follow) {
        SphRun r = measured_run(1.0);
        r.config.ranks = ranks;
        r.intervals.clear();
        const int n = 12;
        double slow = 1;
        for (int v = 0; v < n; ++v) {
            if (spell(rng) < 0.3) // a spell starts or ends
                slow = slow > 1 ? 1 : 1.3 + 0.5 * spell(rng);
            IntervalStats iv;
            iv.step = 100 * (v + 1);
            iv.time_s = 0.01 * (v + 1);
            const double t = (v + 0.5) / n;
            for (int k = 0; k < ranks; ++k) {
                RankStats rk;
                rk.steps = 100;
                rk.field = 1000;
                rk.interactions = 40000;
                const double cost = 30e-9 * (1 + 0.3 * k) * (1 + 0.2 * t + 0.1 * t * t) *
                                    std::pow(slow, follow) * std::exp(noise(rng));
                rk.timers = {
                    {"comp_s", cost * rk.interactions * rk.steps}, {"comm_s", 0}, {"wait_s", 0}};
                rk.gauge_cpu_s = 10 * 40e-6 * slow;
                rk.gauge_samples = 10;
                iv.ranks.push_back(rk);
            }
            r.intervals.push_back(iv);
        }
        return r;
    };
    std::vector<SphRun> runs;
    for (int k = 0; k < 6; ++k)
        runs.push_back(make(k % 2 + 1, planted));
    const auto within = runs;
    runs.push_back(make(3, 1.0)); // above the 2 cores
    // Each interval's own gauge (no pooling), as the planted spells are per interval.
    std::vector<std::vector<double>> gauges;
    for (const auto &r : runs) {
        gauges.emplace_back();
        for (const auto &iv : r.intervals)
            gauges.back().push_back(iv.ranks[0].gauge_cpu_s / iv.ranks[0].gauge_samples);
    }
    const auto e = gauge_elasticity(runs, gauges, 2);
    ASSERT_FALSE(e.is_null());
    EXPECT_EQ(e["groups"].get<int>(), 9); // six runs of 1 or 2 ranks within the cores
    EXPECT_LT(e["se"].get<double>(), 0.02);
    EXPECT_NEAR(e["value"].get<double>(), planted, 3 * e["se"].get<double>());
    // With the run above the cores let in, the estimate moves toward its whole factor.
    EXPECT_GT(gauge_elasticity(runs, gauges, 0)["value"].get<double>(), e["value"].get<double>());
    // One run's gauge flat: no spread left once each group's trend is out.
    std::vector<SphRun> flat{make(1, planted)};
    for (auto &iv : flat[0].intervals)
        iv.ranks[0].gauge_cpu_s = 10 * 40e-6;
    EXPECT_TRUE(gauge_elasticity(flat, {std::vector<double>(12, 40e-6)}, 2).is_null());

    // Applied: fitted leaves less of the gauge in the times than one does. The pooled-window
    // gauge blurs the spells' edges, so compare the spread of ln(compute per interaction).
    auto spread = [](const std::vector<SphRun> &rs) {
        std::vector<double> v;
        for (const auto &r : rs)
            for (const auto &iv : r.intervals)
                v.push_back(std::log(iv.ranks[0].compute_s()));
        const double m = std::accumulate(v.begin(), v.end(), 0.0) / v.size();
        double ss = 0;
        for (double x : v)
            ss += (x - m) * (x - m);
        return std::sqrt(ss / v.size());
    };
    auto fitted = within, whole = within;
    const auto jf = speed_normalise(fitted, SpeedGauge::interval, GaugeReference::pooled,
                                    GaugeElasticity::fitted, 2);
    const auto jo = speed_normalise(whole, SpeedGauge::interval, GaugeReference::pooled,
                                    GaugeElasticity::one, 2);
    const double used = jf["elasticity"]["used"].get<double>();
    EXPECT_GT(used, 0.3);
    EXPECT_LT(used, 0.7);
    EXPECT_DOUBLE_EQ(jo["elasticity"]["used"].get<double>(), 1.0);
    // Reported either way; fitted uses the estimate between repeats (these runs are three
    // repeats each of one configuration on 1 and on 2 ranks).
    EXPECT_NEAR(jo["elasticity"]["between_repeats"]["value"].get<double>(), used, 1e-12);
    EXPECT_EQ(jo["elasticity"]["between_repeats"]["configurations"].get<int>(), 2);
    EXPECT_NEAR(jf["runs"][0]["applied_factor"].get<double>(),
                std::pow(jf["runs"][0]["factor"].get<double>(), used), 1e-12);
    EXPECT_LT(spread(fitted), spread(whole));
    EXPECT_DOUBLE_EQ(gauge_elasticity_for(jf), used);
    EXPECT_DOUBLE_EQ(gauge_elasticity_for(jo), 1.0);
    EXPECT_DOUBLE_EQ(gauge_elasticity_for(nlohmann::json(nullptr)), 1.0);
}

// The elasticity between repeats, against the one within runs, where the gauge's samples are
// noisy as this VM's are (a 30 us sample: interrupts, the other vCPU): each run's host speed
// is its own (a spell the length of a run), its compute follows it with a planted 0.9 and its
// intervals' gauge reads the speed times a noise of 15 %. Within runs the noise is most of the
// gauge's spread and flattens the slope toward 0; each run's whole gauge averages it out, so
// the estimate between repeats recovers the planted value. Runs without repeats add nothing
// to it; without any repeat it is null.
TEST(Calibrate, GaugeElasticityBetweenRepeatsIsNotFlattenedBySampleNoise) {
    constexpr double planted = 0.9;
    std::mt19937 rng(11);
    std::normal_distribution<double> sample_noise(0, 0.15), host(0, 0.2), drift(0, 0.03);
    auto make = [&](double scale) {
        SphRun r = measured_run(1.0);
        r.config.scale = scale;
        r.intervals.clear();
        double speed = std::exp(host(rng));
        for (int v = 0; v < 40; ++v) {
            speed *= std::exp(drift(rng)); // the host wanders a little within the run too
            IntervalStats iv;
            iv.step = 10 * (v + 1);
            iv.time_s = 0.001 * (v + 1);
            RankStats rk;
            rk.steps = 10;
            rk.field = 1000;
            rk.interactions = 40000 * scale;
            const double cost = 30e-9 * std::pow(speed, planted);
            rk.timers = {
                {"comp_s", cost * rk.interactions * rk.steps}, {"comm_s", 0}, {"wait_s", 0}};
            rk.gauge_cpu_s = 40e-6 * speed * std::exp(sample_noise(rng));
            rk.gauge_samples = 1;
            iv.ranks.push_back(rk);
            r.intervals.push_back(iv);
        }
        return r;
    };
    std::vector<SphRun> runs;
    for (int c = 0; c < 8; ++c)
        for (int k = 0; k < 3; ++k)
            runs.push_back(make(0.5 + 0.1 * c));
    std::vector<std::vector<double>> gauges;
    for (const auto &r : runs)
        gauges.push_back(r.interval_gauges_s(speed_gauge_half_window, SphRun::Pooling::median));
    const auto within = gauge_elasticity(runs, gauges, 2);
    const auto between = gauge_elasticity_between_repeats(runs, 2);
    ASSERT_FALSE(within.is_null());
    ASSERT_FALSE(between.is_null());
    EXPECT_EQ(between["configurations"].get<int>(), 8);
    EXPECT_EQ(between["runs"].get<int>(), 24);
    EXPECT_NEAR(between["value"].get<double>(), planted, 3 * between["se"].get<double>());
    EXPECT_LT(between["se"].get<double>(), 0.1);
    EXPECT_LT(within["value"].get<double>(), planted - 3 * within["se"].get<double>());
    // Runs of a configuration run once add nothing; no repeats, no estimate.
    auto more = runs;
    more.push_back(make(2.0));
    EXPECT_DOUBLE_EQ(gauge_elasticity_between_repeats(more, 2)["value"].get<double>(),
                     between["value"].get<double>());
    EXPECT_TRUE(gauge_elasticity_between_repeats({runs[0], runs[3], runs[6]}, 2).is_null());
}

// The core latency of a run of two threads: the mean of its samples' round trips and the share
// of them in rank-intervals whose mean is far; none without samples (one thread, threads taking
// turns, older reports).
TEST(SphRunReport, CoreLatencyIsTheSamplesMeanAndItsFarShare) {
    SphRun r = measured_run(1.0);
    EXPECT_TRUE(r.core_latency_json().is_null());
    r.intervals.push_back(r.intervals[0]);
    r.intervals.push_back(r.intervals[0]);
    const double trips[3] = {60e-9, 65e-9, 330e-9};
    for (int k = 0; k < 3; ++k) {
        r.intervals[k].ranks[0].core_round_trip_s = 10 * trips[k];
        r.intervals[k].ranks[0].core_round_trip_samples = 10;
    }
    r.intervals[2].ranks[0].core_round_trip_samples = 20; // a longer interval, the same mean
    r.intervals[2].ranks[0].core_round_trip_s = 20 * trips[2];
    const auto j = r.core_latency_json();
    ASSERT_FALSE(j.is_null());
    EXPECT_NEAR(j["round_trip_s"].get<double>(), (600e-9 + 650e-9 + 6600e-9) / 40, 1e-15);
    EXPECT_DOUBLE_EQ(j["far_fraction"].get<double>(), 0.5);
    EXPECT_DOUBLE_EQ(j["samples"].get<double>(), 40);
    EXPECT_DOUBLE_EQ(j["far_above_s"].get<double>(), SphRun::far_core_round_trip_s);
}

// --speed-gauge-reference grid: each grid and thread count's runs at their own median gauge.
// Two table runs whose gauge reads 1.2 and two sorted runs whose gauge reads 1.0 (the same host
// speed, the gauge biased by what runs around it) keep their times; pooled scales each pair by
// its gauge over the median of all four. A prediction reads its own group's reference.
TEST(Calibrate, GridGaugeReferenceNormalisesEachGridByItsOwnRuns) {
    auto run = [](const std::string &grid, int threads, double gauge) {
        SphRun r = measured_run(2.0);
        r.config.grid = grid;
        r.config.threads = threads;
        auto &rk = r.intervals[0].ranks[0];
        rk.gauge_cpu_s = 20 * 40e-6 * gauge;
        rk.gauge_samples = 20;
        return r;
    };
    const std::vector<SphRun> base{run("table", 1, 1.2), run("table", 1, 1.2),
                                   run("sorted", 1, 1.0), run("sorted", 1, 1.0)};
    auto grid = base;
    const auto g = speed_normalise(grid, SpeedGauge::run, GaugeReference::grid);
    ASSERT_TRUE(g["applied"].get<bool>());
    EXPECT_EQ(g["reference"], "grid");
    for (const auto &r : grid)
        EXPECT_NEAR(r.wall_s, 2.0, 1e-12);
    EXPECT_NEAR(gauge_reference_for(g, "table", 1).get<double>(), 48e-6, 1e-15);
    EXPECT_NEAR(gauge_reference_for(g, "sorted", 1).get<double>(), 40e-6, 1e-15);
    // No group of its own (another thread count): the pooled median.
    EXPECT_NEAR(gauge_reference_for(g, "sorted", 2).get<double>(), 44e-6, 1e-15);
    auto pooled = base;
    const auto p = speed_normalise(pooled, SpeedGauge::run, GaugeReference::pooled);
    EXPECT_FALSE(p.contains("references"));
    EXPECT_NEAR(pooled[0].wall_s, 2.0 * 44.0 / 48.0, 1e-12);
    EXPECT_NEAR(pooled[2].wall_s, 2.0 * 44.0 / 40.0, 1e-12);
    // The host's mean speed over the calibration against the median run's: the four runs'
    // compute (1 s each) as measured over the same at the reference speed.
    EXPECT_NEAR(p["mean_factor"]["value"].get<double>(), 4.0 / (2 * 44.0 / 48.0 + 2 * 44.0 / 40.0),
                1e-12);
    EXPECT_NEAR(gauge_reference_for(p, "table", 1).get<double>(), 44e-6, 1e-15);
    EXPECT_TRUE(gauge_reference_for(nlohmann::json{{"applied", false}}, "table", 1).is_null());
}

// The host's drift within runs (run_drift, session 79): runs of 8-20 intervals of 0.2 s, each at
// its own level (0.9-1.2 times 40 us a gauge sample), whose gauge reads 0.96 of its start from
// 1 s on: the profile is 0 before 1 s and ln 0.96 from there (carried to the bins no run
// reaches), whatever the levels; the setup's held drift is exp(profile) over its compute; a
// time-shared run (3 ranks on 2 cores) with any drift stays out; too few runs: null.
TEST(Calibrate, RunDriftRecoversAPlantedProfileWithinRuns) {
    auto run = [](int intervals, double level, double late, int ranks = 1) {
        SphRun r = measured_run(0.2 * intervals);
        r.config.ranks = ranks;
        const IntervalStats first = r.intervals[0];
        r.intervals.clear();
        for (int k = 0; k < intervals; ++k) {
            IntervalStats iv = first;
            iv.step = (k + 1) * 100;
            auto &rk = iv.ranks[0];
            rk.timers = {{"pairs_s", 0.1}, {"comp_s", 0.1}, {"comm_s", 0}, {"wait_s", 0}};
            const double middle = (k + 0.5) * 0.2;
            rk.gauge_samples = 10;
            rk.gauge_cpu_s = 10 * 40e-6 * level * (middle >= 1 ? late : 1.0);
            r.intervals.push_back(iv);
        }
        return r;
    };
    std::vector<SphRun> runs{run(8, 1.0, 0.96), run(12, 1.1, 0.96), run(16, 0.9, 0.96),
                             run(20, 1.2, 0.96), run(20, 1.0, 0.5, 3)};
    const auto d = run_drift(runs, 2);
    ASSERT_TRUE(d.is_object());
    EXPECT_EQ(d["runs"], 4);
    const auto edges = d["edges_s"].get<std::vector<double>>();
    const auto profile = d["ln_profile"].get<std::vector<double>>();
    ASSERT_EQ(edges.size(), profile.size());
    for (std::size_t b = 0; b < profile.size(); ++b)
        EXPECT_NEAR(profile[b], edges[b] >= 1 ? std::log(0.96) : 0.0, 1e-9) << edges[b];
    // 56 intervals of the four runs within the cores, 36 of them from 1 s on.
    ASSERT_EQ(d["per_setup"].size(), 1u);
    EXPECT_NEAR(d["per_setup"][0]["mean_drift"].get<double>(), (20 + 36 * 0.96) / 56, 1e-9);
    EXPECT_EQ(d["per_setup"][0]["setup"], "dambreak");
    // speed_normalise carries it.
    auto copy = runs;
    EXPECT_EQ(speed_normalise(copy, SpeedGauge::interval, GaugeReference::pooled,
                              GaugeElasticity::one, 2)["run_drift"],
              d);
    // One run spanning two bins says nothing about a profile.
    EXPECT_TRUE(run_drift({run(20, 1.0, 0.96)}, 2).is_null());
}

// The pipeline bubble of time-shared cores (sharing_bubble, session 80): 3- and 4-rank runs on 2
// cores, bound round-robin, whose intervals' longest timers are the step replayed from their
// CPU per segment times 1 + 0.01 + 0.15 phi (phi 0.3 to 1 on 4 ranks, 0 on 3). The fit
// recovers 0.15 and 0.01 exactly; a run of two threads, one placed otherwise, one without its CPU
// segments and one within the cores stay out; without intervals of both kinds: null.
TEST(Calibrate, SharingBubbleRecoversAPlantedSlopeOverPhi) {
    constexpr double a = 0.01, k = 0.15;
    const std::vector<int> rr{0, 1, 0, 1};
    auto run = [&](std::vector<std::vector<double>> loads, std::vector<int> pus, int threads = 1,
                   bool segments = true) {
        SphRun r = measured_run(1.0);
        const int P = static_cast<int>(loads.front().size());
        r.config.ranks = P;
        r.config.threads = threads;
        r.placement_pus = pus;
        const IntervalStats first = r.intervals[0];
        r.intervals.clear();
        for (std::size_t i = 0; i < loads.size(); ++i) {
            IntervalStats iv = first;
            iv.step = static_cast<std::int64_t>(i + 1) * 100;
            std::vector<std::array<double, 3>> cpu;
            std::vector<int> core_of;
            for (int q = 0; q < P; ++q) {
                const double c = loads[i][static_cast<std::size_t>(q)];
                cpu.push_back({0.35 * c, 0.01 * c, 0.64 * c});
                core_of.push_back(q % 2);
            }
            const double step = replay_time_shared(cpu, core_of, default_replay_slice_s).step_s *
                                (1 + a + k * sharing_bubble_phi(loads[i], core_of));
            iv.ranks.assign(static_cast<std::size_t>(P), first.ranks[0]);
            for (int q = 0; q < P; ++q) {
                auto &rk = iv.ranks[static_cast<std::size_t>(q)];
                rk.steps = 100;
                rk.has_segment_cpu = segments;
                for (std::size_t s = 0; s < 3; ++s)
                    rk.segment_cpu_s[s] = 100 * cpu[static_cast<std::size_t>(q)][s];
                rk.timers = {{"comp_s", 100 * step}};
            }
            r.intervals.push_back(iv);
        }
        return r;
    };
    const std::vector<std::vector<double>> four{{2e-3, 2e-3, 2e-3, 2e-3},
                                                {3e-3, 2e-3, 1.5e-3, 2e-3},
                                                {1e-3, 3e-3, 3e-3, 0.9e-3},
                                                {2e-3, 1.5e-3, 1.4e-3, 2.5e-3}};
    const std::vector<std::vector<double>> three{
        {2e-3, 2e-3, 2e-3}, {4e-3, 1e-3, 0.1e-3}, {1e-3, 2e-3, 3e-3}};
    const std::vector<SphRun> runs{run(four, rr),
                                   run(three, {0, 1, 0}),
                                   run(four, rr, 2),             // two threads per rank: out
                                   run(four, {0, 0, 1, 1}),      // not round-robin: out
                                   run(four, rr, 1, false),      // no CPU segments: out
                                   run({{2e-3, 2e-3}}, {0, 1})}; // within the cores: out
    const auto b = sharing_bubble(runs, 2);
    ASSERT_TRUE(b.is_object());
    EXPECT_NEAR(b["per_phi"].get<double>(), k, 1e-9);
    EXPECT_NEAR(b["intercept"].get<double>(), a, 1e-9);
    EXPECT_EQ(b["intervals"], 7);
    EXPECT_EQ(b["intervals_phi_at_least_half"], 3); // phi 1, 0.5, 0.6 (0.3 below)
    EXPECT_EQ(b["intervals_phi_below_half"], 4);
    EXPECT_EQ(b["slice_s"], default_replay_slice_s);
    ASSERT_EQ(b["runs"].size(), 2u);
    // Only one kind of interval: no slope to tell.
    EXPECT_TRUE(sharing_bubble({runs[0]}, 2).is_null());
    EXPECT_TRUE(sharing_bubble({runs[1]}, 2).is_null());
}

// The host's mean speed per grid, thread count and setup (mean_factor.per_setup, session 76):
// each group's compute as measured over the same at the reference speed. Two table dam breaks
// ran fast (gauge 0.8 and 1.0) and two table still tanks at 1.0 and 1.2: the pooled median
// reference is 1.0, the dam breaks' factor 2 / (1/0.8 + 1) = 0.889, the still tanks'
// 2 / (1 + 1/1.2) = 1.091, and the pooled one 4 / (1.25 + 1 + 1 + 0.833) = 0.981.
TEST(Calibrate, MeanFactorPerSetupIsEachSetupsOwnRunsMeanSpeed) {
    auto run = [](const std::string &setup, double gauge) {
        SphRun r = measured_run(2.0);
        r.config.setup = setup;
        auto &rk = r.intervals[0].ranks[0];
        rk.gauge_cpu_s = 20 * 40e-6 * gauge;
        rk.gauge_samples = 20;
        return r;
    };
    std::vector<SphRun> runs{run("dambreak", 0.8), run("dambreak", 1.0), run("still", 1.0),
                             run("still", 1.2)};
    const auto g = speed_normalise(runs, SpeedGauge::run, GaugeReference::pooled);
    ASSERT_TRUE(g["mean_factor"].contains("per_setup"));
    EXPECT_NEAR(g["mean_factor"]["value"].get<double>(), 4.0 / (1.25 + 1 + 1 + 1 / 1.2), 1e-12);
    std::map<std::string, double> by_setup;
    for (const auto &row : g["mean_factor"]["per_setup"]) {
        EXPECT_EQ(row["grid"], "table");
        EXPECT_EQ(row["threads"], 1);
        EXPECT_EQ(row["runs"], 2);
        by_setup[row["setup"].get<std::string>()] = row["value"].get<double>();
    }
    ASSERT_EQ(by_setup.size(), 2U);
    EXPECT_NEAR(by_setup["dambreak"], 2.0 / (1 / 0.8 + 1), 1e-12);
    EXPECT_NEAR(by_setup["still"], 2.0 / (1 + 1 / 1.2), 1e-12);
}

// With --speed-gauge interval a host that slows down within a run is taken out interval by
// interval: a run of six intervals whose last three ran 1.5 times slower (their times and
// their gauge) comes out flat at the reference speed, where one factor per run leaves the
// step; the gauge of an interval is pooled over +-1 interval (speed_gauge_half_window), as the
// compute-weighted median (interval) or mean (interval-mean, sessions 51-53).
TEST(Calibrate, IntervalSpeedGaugeTakesOutASlowdownWithinARun) {
    auto run = [](const std::vector<double> &slow) {
        SphRun r = measured_run(6.0);
        const IntervalStats first = r.intervals[0];
        r.intervals.clear();
        for (std::size_t k = 0; k < slow.size(); ++k) {
            IntervalStats iv = first;
            iv.step = static_cast<std::int64_t>(k + 1) * 10;
            auto &rk = iv.ranks[0];
            for (auto &[name, v] : rk.timers)
                v = (name == "comm_s" ? 0.1 : 0.5) * slow[k];
            rk.gauge_cpu_s = 10 * 40e-6 * slow[k];
            rk.gauge_samples = 10;
            r.intervals.push_back(iv);
        }
        return r;
    };
    const std::vector<double> steady(6, 1.0), step{1.0, 1.0, 1.0, 1.5, 1.5, 1.5};
    ASSERT_EQ(speed_gauge_half_window, 1);
    // The median of each window: the step is taken out where it happened, every interval back
    // at 0.5 s.
    std::vector<SphRun> runs{run(steady), run(steady), run(step)};
    const auto j = speed_normalise(runs, SpeedGauge::interval);
    ASSERT_TRUE(j["applied"].get<bool>());
    EXPECT_EQ(j["mode"], "interval");
    EXPECT_NEAR(j["reference_cpu_s_per_sample"].get<double>(), 40e-6, 1e-15);
    const auto &median_factors = j["runs"][2]["interval_factors"];
    ASSERT_EQ(median_factors.size(), step.size());
    for (std::size_t k = 0; k < step.size(); ++k) {
        EXPECT_NEAR(median_factors[k].get<double>(), step[k], 1e-12);
        EXPECT_NEAR(runs[2].intervals[k].ranks[0].timer("pairs_s"), 0.5, 1e-12);
    }
    // The wall (as measured, 6 s) as the sum of its intervals, each divided by its own factor
    // and weighted by its compute: here 6 x (3 x 1 + 3 x 1.5 / 1.5) / (3 x 1 + 3 x 1.5).
    EXPECT_NEAR(runs[2].wall_s, 6.0 * 6.0 / 7.5, 1e-12);
    // The mean of each window (sessions 51-53): at the step (0.5 x 40 + 0.5 x 40 + 0.75 x 60) /
    // 1.75 and its mirror image.
    std::vector<SphRun> mean_runs{run(steady), run(steady), run(step)};
    const auto m = speed_normalise(mean_runs, SpeedGauge::interval_mean);
    EXPECT_EQ(m["mode"], "interval-mean");
    const double at_3 = (0.5 * 40 + 0.5 * 40 + 0.75 * 60) / 1.75 / 40;
    const double at_4 = (0.5 * 40 + 0.75 * 60 + 0.75 * 60) / 2.0 / 40;
    const std::vector<double> want{1.0, 1.0, at_3, at_4, 1.5, 1.5};
    const auto &factors = m["runs"][2]["interval_factors"];
    ASSERT_EQ(factors.size(), want.size());
    for (std::size_t k = 0; k < want.size(); ++k) {
        EXPECT_NEAR(factors[k].get<double>(), want[k], 1e-12);
        EXPECT_NEAR(mean_runs[2].intervals[k].ranks[0].timer("pairs_s"), 0.5 * step[k] / want[k],
                    1e-12);
    }
    EXPECT_NEAR(mean_runs[2].intervals[5].ranks[0].timer("comp_s"), 0.5, 1e-12);
    double weighted = 0, weight = 0;
    for (std::size_t k = 0; k < want.size(); ++k) {
        weighted += step[k] / want[k];
        weight += step[k];
    }
    EXPECT_NEAR(mean_runs[2].wall_s, 6.0 * weighted / weight, 1e-12);
    // One factor per run leaves the step in: the last interval stays 1.5 times the first.
    std::vector<SphRun> whole{run(steady), run(steady), run(step)};
    speed_normalise(whole, SpeedGauge::run);
    EXPECT_NEAR(whole[2].intervals[5].ranks[0].timer("comp_s") /
                    whole[2].intervals[0].ranks[0].timer("comp_s"),
                1.5, 1e-12);
}

// One disturbed gauge sample (a host interrupt inside 30 us of arithmetic: it read 3 times the
// others while the interval's compute did not move, as in session 54's calibration runs) leaves
// the run as measured with the window's median; the mean takes it for a slowdown of the three
// intervals around it and makes them up to a quarter cheaper than they ran.
TEST(Calibrate, OneDisturbedGaugeSampleDoesNotRescaleTheIntervalsAroundIt) {
    auto run = [](std::size_t spiked) {
        SphRun r = measured_run(6.0);
        const IntervalStats first = r.intervals[0];
        r.intervals.clear();
        for (std::size_t k = 0; k < 6; ++k) {
            IntervalStats iv = first;
            iv.step = static_cast<std::int64_t>(k + 1) * 10;
            auto &rk = iv.ranks[0];
            for (auto &[name, v] : rk.timers)
                v = name == "comm_s" ? 0.1 : 0.5;
            rk.gauge_samples = 2;
            // Two samples of 40 us, or one of them at 120 us.
            rk.gauge_cpu_s = k == spiked ? 160e-6 : 80e-6;
            r.intervals.push_back(iv);
        }
        return r;
    };
    constexpr std::size_t none = 99;
    std::vector<SphRun> median_runs{run(none), run(none), run(2)};
    speed_normalise(median_runs, SpeedGauge::interval);
    for (std::size_t k = 0; k < 6; ++k)
        EXPECT_NEAR(median_runs[2].intervals[k].ranks[0].timer("pairs_s"), 0.5, 1e-12) << k;
    EXPECT_NEAR(median_runs[2].wall_s, 6.0, 1e-12);
    std::vector<SphRun> mean_runs{run(none), run(none), run(2)};
    speed_normalise(mean_runs, SpeedGauge::interval_mean);
    for (std::size_t k = 1; k <= 3; ++k)
        EXPECT_NEAR(mean_runs[2].intervals[k].ranks[0].timer("pairs_s"), 0.5 / (80.0 / 60), 1e-12)
            << k;
}

// A prediction's band (+-2 sd of ln(time)): with a 5 % scatter, a run 20 % faster than
// predicted lies outside it (z = ln(1/1.2)/0.05 = -3.65), one 5 % slower inside (z = 0.98); a
// prediction without a band is not counted.
TEST(Validate, ChecksTheMeasuredRunAgainstThePredictionsBand) {
    auto banded = [](double wall_s, double sd) {
        auto p = prediction(wall_s);
        p["configurations"][0]["wall_band"] = {{"log_sd", sd},
                                               {"dof", 10},
                                               {"sds", 2},
                                               {"low_s", wall_s * std::exp(-2 * sd)},
                                               {"high_s", wall_s * std::exp(2 * sd)}};
        return p;
    };
    auto twice = measured_run(1.05);
    twice.config.ranks = 2;
    auto p2 = banded(1.0, 0.05);
    p2["configurations"][0]["ranks"] = 2;
    bool exceeded = false;
    const auto v = validate({}, {banded(1.2, 0.05), p2}, {measured_run(1.0), twice}, {}, exceeded);
    const auto &c = v["configurations"];
    ASSERT_EQ(c.size(), 2u);
    EXPECT_NEAR(c[0]["wall_band"]["z"].get<double>(), std::log(1.0 / 1.2) / 0.05, 1e-9);
    EXPECT_FALSE(c[0]["wall_band"]["within"].get<bool>());
    EXPECT_NEAR(c[1]["wall_band"]["z"].get<double>(), std::log(1.05) / 0.05, 1e-9);
    EXPECT_TRUE(c[1]["wall_band"]["within"].get<bool>());
    EXPECT_EQ(v["summary"]["wall_band"]["within"], 1);
    EXPECT_EQ(v["summary"]["wall_band"]["count"], 2);
    // The noise floor is drawn from the two bands' deviations.
    EXPECT_EQ(v["summary"]["wall_noise_floor"]["configurations"], 2);
    EXPECT_GT(v["summary"]["wall_noise_floor"]["max_abs_error"]["median"].get<double>(), 0);
    const auto none = validate({}, {prediction(1.2)}, {measured_run(1.0)}, {}, exceeded);
    EXPECT_TRUE(none["configurations"][0]["wall_band"].is_null());
    EXPECT_TRUE(none["summary"]["wall_band"].is_null());
    EXPECT_TRUE(none["summary"]["wall_noise_floor"].is_null());
}

// A model exact in expectation, on runs whose ln(time) scatters by sd: one configuration's
// |error| has the median of |exp(sd z) - 1|, about 0.674 sd for a small sd (the median of |z|);
// the max over 19 configurations the expected max of 19 |z|, about 2.2 sd; no scatter, no error.
TEST(Validate, NoiseFloorOfAModelExactInExpectation) {
    const std::vector<double> one{0.01};
    const auto f1 = wall_noise_floor(one);
    EXPECT_EQ(f1.configurations, 1u);
    EXPECT_NEAR(f1.median_abs_error.median, 0.6745 * 0.01, 0.03 * 0.6745 * 0.01);
    EXPECT_DOUBLE_EQ(f1.max_abs_error.median, f1.median_abs_error.median);
    EXPECT_LT(f1.median_abs_error.p05, 0.1 * 0.01); // |z| < 0.063 one draw in 20
    EXPECT_NEAR(f1.median_abs_error.p95, 1.96 * 0.01, 0.05 * 1.96 * 0.01);

    const std::vector<double> many(19, 0.01);
    const auto f = wall_noise_floor(many);
    EXPECT_GT(f.max_abs_error.median, 2.0 * 0.01);
    EXPECT_LT(f.max_abs_error.median, 2.4 * 0.01);
    EXPECT_LT(f.max_abs_error.p05, f.max_abs_error.median);
    EXPECT_GT(f.max_abs_error.p95, f.max_abs_error.median);
    // The median over 19 configurations is far less spread than one configuration's error.
    EXPECT_NEAR(f.median_abs_error.median, 0.6745 * 0.01, 0.05 * 0.6745 * 0.01);
    EXPECT_GT(f.median_abs_error.p05, 0.4 * 0.01);
    EXPECT_LT(f.median_abs_error.p95, 1.0 * 0.01);

    const std::vector<double> still(5, 0.0);
    const auto f0 = wall_noise_floor(still);
    EXPECT_EQ(f0.max_abs_error.p95, 0);
    EXPECT_EQ(wall_noise_floor(std::vector<double>{}).configurations, 0u);
}

// The latency probe sorts each interval's inline communication error by the machine's mode:
// the app's probe reads 1.4x the profile's figure in the same mode and the modes differ 2.5x,
// so a probe at 1.4x or 1.8x is in the profile's mode, at 3.5x or 0.56x not, and a run that did
// not probe counts in neither.
TEST(Validate, SplitsInlineCommunicationErrorsByLatencyMode) {
    auto run = [](double probe_s, double profile_s, double predicted_s) {
        auto r = measured_run(1.0);
        r.intervals[0].ranks[0].timers["comm_s"] = 0.1;
        r.intervals[0].ranks[0].comm_predict_s = predicted_s;
        r.intervals[0].ranks[0].probe_shift_s = probe_s;
        r.profile_probe_shift_s = profile_s;
        return r;
    };
    bool exceeded = false;
    const auto v = validate({}, {prediction(1.0)},
                            {run(1.4e-6, 1e-6, 0.11), run(3.5e-6, 1e-6, 0.05),
                             run(0.56e-6, 1e-6, 0.05), run(1.8e-6, 1e-6, 0.13), run(0, 0, 0.2)},
                            {}, exceeded);
    const auto &s = v["summary"];
    ASSERT_EQ(s["inline_comm_abs_error_per_interval_profile_mode"]["count"], 2);
    EXPECT_NEAR(s["inline_comm_abs_error_per_interval_profile_mode"]["median"].get<double>(), 0.2,
                1e-12);
    ASSERT_EQ(s["inline_comm_abs_error_per_interval_other_mode"]["count"], 2);
    EXPECT_NEAR(s["inline_comm_abs_error_per_interval_other_mode"]["median"].get<double>(), 0.5,
                1e-12);
    EXPECT_EQ(s["inline_comm_abs_error_per_interval"]["count"], 5);
    EXPECT_NEAR(v["configurations"][1]["comm_series"][0]["probe_over_profile"].get<double>(), 3.5,
                1e-12);
}

// Each exchange's inline error apart: a migration predicted 50 % high, ghosts 10 % low, and
// densities the run never measured (a report without them), which count in no median.
TEST(Validate, SplitsInlineCommunicationErrorsByExchange) {
    auto r = measured_run(1.0);
    auto &rank = r.intervals[0].ranks[0];
    rank.shift_comm_s = {0.02, 0.05, 0};
    rank.shift_predict_s = {0.03, 0.045, 0.01};
    bool exceeded = false;
    const auto v = validate({}, {prediction(1.0)}, {r}, {}, exceeded);
    const auto &by = v["summary"]["inline_comm_abs_error_per_interval_by_shift"];
    EXPECT_NEAR(by["migration"]["median"].get<double>(), 0.5, 1e-12);
    EXPECT_NEAR(by["ghosts"]["median"].get<double>(), 0.1, 1e-12);
    EXPECT_TRUE(by["densities"].is_null());
    const auto &e = v["configurations"][0]["comm_series"][0]["shifts"];
    EXPECT_NEAR(e["ghosts"]["inline_error"].get<double>(), -0.1, 1e-12);
    EXPECT_FALSE(e.contains("densities"));
}

// The inline error by the rule before session 32 (recorded per exchange beside the rule in
// use): the interval's prediction with each exchange's own-kind figure in place of its own. A
// report without them (older) predicted by that rule: its comm_predict_s stands in.
TEST(Validate, ReportsTheInlineErrorOfTheRuleBefore) {
    auto r = measured_run(1.0);
    auto &rank = r.intervals[0].ranks[0];
    rank.timers["comm_s"] = 0.1;
    rank.comm_predict_s = 0.11;
    rank.shift_predict_s = {0.03, 0.05, 0.03};
    rank.shift_predict_own_kind_s = {0.05, 0.05, 0.04}; // 0.03 more in all
    auto older = measured_run(1.0);
    older.intervals[0].ranks[0].timers["comm_s"] = 0.1;
    older.intervals[0].ranks[0].comm_predict_s = 0.12;
    bool exceeded = false;
    const auto v = validate({}, {prediction(1.0)}, {r, older}, {}, exceeded);
    EXPECT_NEAR(v["configurations"][0]["comm_series"][0]["inline_own_kind_gap_error"].get<double>(),
                0.4, 1e-12);
    EXPECT_NEAR(v["configurations"][1]["comm_series"][0]["inline_own_kind_gap_error"].get<double>(),
                0.2, 1e-12);
    const auto &s = v["summary"]["inline_comm_abs_error_per_interval_own_kind_gap"];
    EXPECT_EQ(s["count"], 2);
    EXPECT_NEAR(s["median"].get<double>(), 0.3, 1e-12);
}

namespace {
constexpr double planted_per_interaction = 2e-8, planted_scale = 0.5, planted_dt = 1e-4;
constexpr int planted_steps = 10;
// Two rounds of a half-scale dam break on Cell+Table, equal work every interval (100 field
// particles, 4000 interactions), the busy rank's pair time the planted cost per interaction
// times factor(round, interval, Froude time of its midpoint); with `idle_rank` a second rank
// without water whose bookkeeping must stay out of the profile. Also the compute entry that
// prices an interaction at exactly the planted cost.
struct PlantedProfile {
    std::vector<SphRun> runs;
    nlohmann::json entry;
    std::vector<const SphRun *> pointers() const { return {&runs[0], &runs[1]}; }
};
PlantedProfile planted_profile(int intervals, bool idle_rank,
                               const std::function<double(std::size_t, int, double)> &factor) {
    PlantedProfile out;
    out.runs.resize(2);
    for (std::size_t n = 0; n < out.runs.size(); ++n) {
        SphRun &r = out.runs[n];
        r.config.setup = "dambreak";
        r.config.grid = "table";
        r.config.scale = planted_scale;
        r.config.dt = planted_dt;
        r.config.ranks = idle_rank ? 2 : 1;
        for (int k = 1; k <= intervals; ++k) {
            IntervalStats iv;
            iv.step = k * planted_steps;
            iv.time_s = iv.step * planted_dt;
            const double tf =
                (iv.time_s - 0.5 * planted_steps * planted_dt) / std::sqrt(planted_scale);
            RankStats busy;
            busy.steps = planted_steps;
            busy.field = busy.field_mean = 100;
            busy.interactions = 4000;
            busy.timers = {
                {"pairs_s", planted_per_interaction * 4000 * planted_steps * factor(n, k, tf)},
                {"wait_s", 0.5}};
            iv.ranks = {busy};
            if (idle_rank) {
                RankStats idle;
                idle.steps = planted_steps;
                idle.timers = {{"grid_s", 1.0}}; // bookkeeping of a rank without water
                iv.ranks.push_back(idle);
            }
            r.intervals.push_back(iv);
        }
    }
    out.entry = {
        {"terms", {"interactions"}},
        {"coefficients", {{"interactions", {{"value", planted_per_interaction}, {"se", 0.0}}}}},
        {"r2", 1.0},
        {"rse", 0.0},
        {"points", 2 * intervals},
        {"run_level", {{"factor", 1.0}, {"per_setup", nlohmann::json::object()}}}};
    return out;
}
} // namespace

// A cost per interaction planted as a function of Froude time, g(tF) = 1 + 2 tF, in two rounds
// of a half-scale run (equal work every interval): the windowed profile recovers g at each
// interval's Froude time (interval midpoint / sqrt(0.5)), the window's ratio of sums being
// exact for a line, and idle ranks stay out of it.
TEST(TimeProfile, RecoversAPlantedCostOverFroudeTime) {
    constexpr int intervals = 30;
    auto g = [](double tf) { return 1 + 2 * tf; };
    const PlantedProfile d =
        planted_profile(intervals, true, [&](std::size_t, int, double tf) { return g(tf); });
    const auto p = compute_time_profile(d.entry, d.pointers(), false).at("dambreak");
    const auto t = p.at("froude_time_s").get<std::vector<double>>();
    const auto f = p.at("factor").get<std::vector<double>>();
    ASSERT_EQ(t.size(), static_cast<std::size_t>(intervals)); // the rounds share their times
    EXPECT_EQ(p.at("runs"), 2);
    EXPECT_EQ(p.at("smoothing"), "window");
    // Away from the ends (where the window is cut short) every factor is g at its time.
    for (std::size_t k = 2; k + 2 < t.size(); ++k)
        EXPECT_NEAR(f[k], g(t[k]), 1e-9) << "at Froude time " << t[k];
    EXPECT_NEAR(t.back(),
                (intervals * planted_steps - 0.5 * planted_steps) * planted_dt /
                    std::sqrt(planted_scale),
                1e-12);
}

// The smoothed profile (--time-profile froude, session 42): a planted quadratic cost over
// Froude time with 1 % noise, and a slow spell of the host (+20 % for 5 intervals) in one of the
// two runs. The robust quadratic recovers the planted curve within 1 % everywhere, spell
// included, and rejects the spell's intervals; the window's ratio carries half the spell.
TEST(TimeProfile, RobustQuadraticIgnoresASlowSpellInOneRun) {
    constexpr int intervals = 40, spell_from = 10, spell_to = 15;
    auto g = [](double tf) { return 0.95 + 2.0 * tf + 40.0 * tf * tf; };
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, 0.01);
    const PlantedProfile d =
        planted_profile(intervals, false, [&](std::size_t run, int k, double tf) {
            const double spell = run == 0 && k > spell_from && k <= spell_to ? 1.2 : 1.0;
            return g(tf) * spell * (1 + noise(rng));
        });
    const auto p = compute_time_profile(d.entry, d.pointers()).at("dambreak");
    EXPECT_EQ(p.at("smoothing"), "robust quadratic");
    const auto t = p.at("froude_time_s").get<std::vector<double>>();
    const auto f = p.at("factor").get<std::vector<double>>();
    const auto w = p.at("factor_windowed").get<std::vector<double>>();
    ASSERT_EQ(t.size(), static_cast<std::size_t>(intervals));
    double worst = 0, worst_windowed = 0;
    for (std::size_t k = 0; k < t.size(); ++k) {
        worst = std::max(worst, std::abs(f[k] / g(t[k]) - 1));
        worst_windowed = std::max(worst_windowed, std::abs(w[k] / g(t[k]) - 1));
    }
    EXPECT_LT(worst, 0.01);
    EXPECT_GT(worst_windowed, 0.05); // the spell, halved by pooling the rounds
    // The rounds share their times, so a spell interval is pooled with its twin: +10 %, 10
    // standard deviations of the noise, and rejected.
    EXPECT_GE(p.at("intervals_rejected").get<int>(), spell_to - spell_from);
}

// The shape-only profile (--run-level fastest-repeat, session 43): two repeats of one
// configuration, the second 15 % slower throughout (a slow host), on a planted cost g over
// Froude time. Each run's intervals fitted at its own level give g itself, so the level stays
// the rule's (the fastest repeat, 1.0); the pooled profile carries the runs' mean level, 7.5 %
// above g, and overrides it.
TEST(TimeProfile, ShapeOnlyProfileLeavesTheLevelToTheRepeatsRule) {
    constexpr int intervals = 30;
    auto g = [](double tf) { return 1 + 2 * tf; };
    PlantedProfile d = planted_profile(intervals, false, [&](std::size_t run, int, double tf) {
        return g(tf) * (run == 1 ? 1.15 : 1.0);
    });
    d.runs[0].path = "round_a.json";
    d.runs[1].path = "round_b.json";
    // The run factors as calibrate measures them (measured / fitted over the fit's window:
    // here the planted shape's mean cancels, so only the runs' ratio matters).
    d.entry["run_level"]["runs"] = {{{"run", "round_a.json"}, {"factor", 1.0}},
                                    {{"run", "round_b.json"}, {"factor", 1.15}}};
    d.entry["run_level"]["per_setup"] = {
        {"dambreak", {{"factor", 1.0}, {"runs", 2}, {"configurations", 1}}}};
    const auto shape = compute_time_profile(d.entry, d.pointers(), false, true).at("dambreak");
    const auto pooled = compute_time_profile(d.entry, d.pointers(), false, false).at("dambreak");
    const auto t = shape.at("froude_time_s").get<std::vector<double>>();
    const auto fs = shape.at("factor").get<std::vector<double>>();
    const auto fp = pooled.at("factor").get<std::vector<double>>();
    ASSERT_EQ(t.size(), static_cast<std::size_t>(intervals));
    for (std::size_t k = 2; k + 2 < t.size(); ++k) {
        EXPECT_NEAR(fs[k], g(t[k]), 1e-9) << "at Froude time " << t[k];
        EXPECT_NEAR(fp[k], 1.075 * g(t[k]), 1e-9) << "at Froude time " << t[k];
    }
    // Without repeats (one run per configuration) there is no faster run to prefer: the
    // profile stays pooled.
    d.entry["run_level"]["per_setup"]["dambreak"]["configurations"] = 2;
    const auto single = compute_time_profile(d.entry, d.pointers(), false, true).at("dambreak");
    EXPECT_EQ(single.at("factor"), pooled.at("factor"));
}
