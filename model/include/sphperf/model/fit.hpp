#pragma once
// Ordinary least squares with covariance (GSL gsl_multifit_linear), the statistics the thesis
// reports for its regressions (asymptotic standard errors, R^2, residual standard error), and
// leave-one-group-out cross-validation for choosing the terms of a cost model by evidence.
#include <nlohmann/json.hpp>

#include <map>
#include <span>
#include <string>
#include <vector>

namespace sphperf::model {

struct LinearFit {
    std::vector<std::string> terms; // names of the columns of X ("const" is the intercept)
    std::vector<double> coef, se;   // coefficients and asymptotic standard errors
    std::vector<std::vector<double>> cov;
    double r2 = 0;  // 1 - SSR / SST (SST about the mean of y)
    double rse = 0; // residual standard error sqrt(SSR / (n - p))
    std::size_t points = 0;

    double predict(std::span<const double> x) const;
    double coefficient(const std::string &term) const; // 0 when the term is not in the fit
    nlohmann::json to_json() const;
    static LinearFit from_json(const nlohmann::json &j, const std::string &where);
};

// X is row-major, one row per observation, one column per term. Needs more rows than terms and
// full column rank; throws std::invalid_argument otherwise.
LinearFit fit_linear(const std::vector<std::vector<double>> &X, std::span<const double> y,
                     std::vector<std::string> terms);

// Robust least squares (GSL gsl_multifit_robust, Tukey's bisquare): points far from the fit
// lose their weight, so a stretch of outliers (a slow spell of the host in one calibration
// run) does not bend it. `weights` are the final robust weights (0 = rejected). Needs more rows
// than terms; throws std::invalid_argument otherwise.
struct RobustFit {
    LinearFit fit;
    std::vector<double> weights;
};
RobustFit fit_robust(const std::vector<std::vector<double>> &X, std::span<const double> y,
                     std::vector<std::string> terms);

// The thesis' p(n) = m n + r.
LinearFit fit_line_mr(std::span<const double> n, std::span<const double> y);

// Least squares with one multiplicative level per class of rows: y = level[class] (X beta).
// The classes are the setups: an interaction of the dam break costs more than one of the still
// tank at the same counts (its flow, its free surface), and a plain fit pooling both lets a
// term that merely tells the setups apart (a constant, cell moves, walls) absorb that
// difference, then extrapolate it with the scale. Gauss-Newton; the levels are
// normalised to a mean of 1, so `fit` is the cost at the classes' average level. An empty
// `classes`, or a single class, is ordinary least squares.
struct LevelledFit {
    LinearFit fit;
    std::map<int, double> levels; // class -> level
    double level(int cls) const;  // 1 for a class the fit has not seen
    double predict(std::span<const double> x, int cls) const { return level(cls) * fit.predict(x); }
};
LevelledFit fit_levelled(const std::vector<std::vector<double>> &X, std::span<const double> y,
                         std::vector<std::string> terms, std::span<const int> classes);

// Root mean square of the held-out residuals when each group (a calibration run) is left out in
// turn and predicted by a levelled fit to the others (the held-out run at its class's level, as
// predict applies it). With a single group, 5 interleaved folds instead.
double cross_validate(const std::vector<std::vector<double>> &X, std::span<const double> y,
                      std::span<const int> groups, std::span<const int> classes = {});

// The same score with its standard error: the spread of the folds' mean square errors over the
// root of their count, carried to the root mean square (delta method). The one-standard-error
// rule picks the smallest set of terms whose score is within one standard error of the best.
struct CvScore {
    double rmse = 0, rmse_se = 0;
};
CvScore cross_validate_score(const std::vector<std::vector<double>> &X, std::span<const double> y,
                             std::span<const int> groups, std::span<const int> classes = {});

// Which candidate set of terms a rule keeps, given each set's held-out score and its number of
// terms (the index into both). best: the lowest score. one_se: the smallest set whose score is
// within one standard error (the best set's) of the best, ties in size to the lower score.
// one_percent: a set replaces the one kept when it scores 1 % lower, or is smaller and scores
// lower at all (candidates in order of growing sets).
enum class TermRule { best, one_se, one_percent };
std::size_t select_term_set(std::span<const CvScore> scores, std::span<const std::size_t> sizes,
                            TermRule rule);

// Relative weights for a fit over runs of different sizes: each point's unit is the median y of
// its group (its run's typical step, not the point's own noisy value). Dividing a row of X and
// its y by its unit makes every run count by its relative error, as the targets judge it.
std::vector<double> group_median_units(std::span<const double> y, std::span<const int> groups);
// X with row i divided by units[i].
std::vector<std::vector<double>> divided_rows(std::vector<std::vector<double>> X,
                                              std::span<const double> units);

// What a prediction is judged on: each run (group) left out in turn, its summed time predicted
// by a fit to the others; the root mean square over runs of the relative error of that sum.
// Unlike cross_validate, a run of small per-step times counts as much as one of large ones, so a
// term that only matters when the work is extrapolated (to another scale) shows. Needs >= 2 runs.
double cross_validate_runs(const std::vector<std::vector<double>> &X, std::span<const double> y,
                           std::span<const int> groups, std::span<const int> classes = {});

// Run-to-run machine speed: each group's (calibration run's) measured sum over the fit's
// predicted sum. A machine that slows down for minutes (measured here: 35 % for two whole runs)
// moves a least-squares fit by the leverage of those runs; the median of the factors does not.
struct RunLevel {
    std::vector<int> groups;     // in ascending order
    std::vector<double> factors; // measured / fitted, per group
    double median = 1;           // median of factors (mean of the middle two for an even count)
    double mean = 1;             // reported beside: a sum of times pays the mean
    double spread_pct = 0;       // 100 (max / min - 1): how far identical work drifted
};
RunLevel run_level(const LinearFit &f, const std::vector<std::vector<double>> &X,
                   std::span<const double> y, std::span<const int> groups);

// A cost level from runs grouped by configuration (measured / fitted per run): the fastest run of
// each configuration, then the median over configurations. On a host whose disturbances only
// add time, the fastest of identical runs is the least disturbed; one configuration's runs
// cannot outvote another's.
double fastest_repeat_level(const std::map<std::string, std::vector<double>> &by_configuration);

// How far identical-looking calibration runs scatter around their setup's level: the pooled
// sum of squares of ln(factor) about each setup's mean ln(factor), and its degrees of freedom
// (runs less setups). The run-to-run noise of the host plus the fit's misfit between a setup's
// scales: what one more run of the same kind may be off by, not the uncertainty of the level.
struct LevelScatter {
    double sum_sq = 0; // of ln(factor) about the setup's mean ln(factor)
    int dof = 0;       // runs less setups
    int runs = 0;
    LevelScatter &operator+=(const LevelScatter &o);
    // The pooled standard deviation of ln(factor); 0 without a degree of freedom.
    double log_sd() const;
};
// Factors (measured / fitted, positive) by setup.
LevelScatter level_scatter(const std::map<std::string, std::vector<double>> &factors_by_setup);

// The fit scaled by a factor: coefficients, standard errors and covariance (so a level applied
// after the fit keeps its relative uncertainty).
LinearFit scaled(LinearFit f, double factor);

} // namespace sphperf::model
