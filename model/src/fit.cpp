#include "sphperf/model/fit.hpp"

#include "sphperf/errors.hpp"
#include "sphperf/stats.hpp"

#include <gsl/gsl_errno.h>
#include <gsl/gsl_multifit.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <numeric>
#include <set>
#include <stdexcept>

namespace sphperf::model {

namespace {
struct GslFree {
    void operator()(gsl_matrix *m) const { gsl_matrix_free(m); }
    void operator()(gsl_vector *v) const { gsl_vector_free(v); }
    void operator()(gsl_multifit_linear_workspace *w) const { gsl_multifit_linear_free(w); }
    void operator()(gsl_multifit_robust_workspace *w) const { gsl_multifit_robust_free(w); }
};
template <class T> using Owned = std::unique_ptr<T, GslFree>;
} // namespace

double LinearFit::predict(std::span<const double> x) const {
    double s = 0;
    for (std::size_t k = 0; k < coef.size(); ++k)
        s += coef[k] * x[k];
    return s;
}

double LinearFit::coefficient(const std::string &term) const {
    for (std::size_t k = 0; k < terms.size(); ++k)
        if (terms[k] == term)
            return coef[k];
    return 0;
}

nlohmann::json LinearFit::to_json() const {
    nlohmann::json c = nlohmann::json::object();
    for (std::size_t k = 0; k < terms.size(); ++k)
        c[terms[k]] = {{"value", coef[k]},
                       {"se", se[k]},
                       {"se_pct", coef[k] != 0 ? 100.0 * se[k] / std::abs(coef[k]) : 0.0}};
    return {{"terms", terms}, {"coefficients", c}, {"covariance", cov},
            {"r2", r2},       {"rse", rse},        {"points", points}};
}

LinearFit LinearFit::from_json(const nlohmann::json &j, const std::string &where) {
    LinearFit f;
    try {
        f.terms = j.at("terms").get<std::vector<std::string>>();
        for (const auto &t : f.terms) {
            f.coef.push_back(j.at("coefficients").at(t).at("value").get<double>());
            f.se.push_back(j.at("coefficients").at(t).at("se").get<double>());
        }
        f.r2 = j.at("r2").get<double>();
        f.rse = j.at("rse").get<double>();
        f.points = j.at("points").get<std::size_t>();
    } catch (const nlohmann::json::exception &e) {
        throw UsageError(where + ": " + e.what());
    }
    return f;
}

namespace {
// The design matrix, right-hand side and coefficient and covariance outputs of one GSL fit,
// checked for shape (`what` names the fit in the message).
struct GslProblem {
    std::size_t n, p;
    Owned<gsl_matrix> A, C;
    Owned<gsl_vector> b, c;
    GslProblem(const std::vector<std::vector<double>> &X, std::span<const double> y,
               std::size_t terms, const std::string &what)
        : n(X.size()), p(terms) {
        if (n != y.size())
            throw std::invalid_argument(what + ": X and y differ in length");
        if (n <= p)
            throw std::invalid_argument(what + ": " + std::to_string(n) +
                                        " points cannot determine " + std::to_string(p) +
                                        " coefficients");
        A.reset(gsl_matrix_alloc(n, p));
        C.reset(gsl_matrix_alloc(p, p));
        b.reset(gsl_vector_alloc(n));
        c.reset(gsl_vector_alloc(p));
        for (std::size_t i = 0; i < n; ++i) {
            if (X[i].size() != p)
                throw std::invalid_argument(what + ": a row of X has the wrong number of terms");
            for (std::size_t k = 0; k < p; ++k)
                gsl_matrix_set(A.get(), i, k, X[i][k]);
            gsl_vector_set(b.get(), i, y[i]);
        }
    }
    // The solved coefficients, their standard errors and covariance.
    LinearFit solution(std::vector<std::string> terms) const {
        LinearFit f;
        f.terms = std::move(terms);
        f.points = n;
        for (std::size_t k = 0; k < p; ++k) {
            f.coef.push_back(gsl_vector_get(c.get(), k));
            f.se.push_back(std::sqrt(gsl_matrix_get(C.get(), k, k)));
            f.cov.emplace_back();
            for (std::size_t l = 0; l < p; ++l)
                f.cov.back().push_back(gsl_matrix_get(C.get(), k, l));
        }
        return f;
    }
};
} // namespace

LinearFit fit_linear(const std::vector<std::vector<double>> &X, std::span<const double> y,
                     std::vector<std::string> terms) {
    GslProblem q(X, y, terms.size(), "fit");
    Owned<gsl_multifit_linear_workspace> work(gsl_multifit_linear_alloc(q.n, q.p));
    double chisq = 0;
    std::size_t rank = 0;
    // SVD with a relative singular-value cut: a term that is a copy of another is rank lost,
    // which we refuse rather than report meaningless standard errors.
    gsl_set_error_handler_off();
    if (gsl_multifit_linear_tsvd(q.A.get(), q.b.get(), 1e-12, q.c.get(), q.C.get(), &chisq, &rank,
                                 work.get()) != GSL_SUCCESS ||
        rank < q.p)
        throw std::invalid_argument("fit: the terms are linearly dependent on these data");
    LinearFit f = q.solution(std::move(terms));
    const double mean = std::accumulate(y.begin(), y.end(), 0.0) / static_cast<double>(q.n);
    double sst = 0;
    for (double v : y)
        sst += (v - mean) * (v - mean);
    f.r2 = sst > 0 ? 1.0 - chisq / sst : 1.0;
    f.rse = std::sqrt(chisq / static_cast<double>(q.n - q.p));
    return f;
}

RobustFit fit_robust(const std::vector<std::vector<double>> &X, std::span<const double> y,
                     std::vector<std::string> terms) {
    GslProblem q(X, y, terms.size(), "robust fit");
    Owned<gsl_multifit_robust_workspace> work(
        gsl_multifit_robust_alloc(gsl_multifit_robust_bisquare, q.n, q.p));
    gsl_set_error_handler_off();
    // GSL_EMAXITER still leaves the last iterate, a usable fit; anything else is not.
    const int status = gsl_multifit_robust(q.A.get(), q.b.get(), q.c.get(), q.C.get(), work.get());
    if (status != GSL_SUCCESS && status != GSL_EMAXITER)
        throw std::invalid_argument(std::string("robust fit: ") + gsl_strerror(status));
    const gsl_multifit_robust_stats st = gsl_multifit_robust_statistics(work.get());
    RobustFit out{q.solution(std::move(terms)), {}};
    out.fit.r2 = st.Rsq;
    out.fit.rse = st.sigma;
    for (std::size_t i = 0; i < q.n; ++i)
        out.weights.push_back(gsl_vector_get(st.weights, i));
    return out;
}

LinearFit fit_line_mr(std::span<const double> n, std::span<const double> y) {
    std::vector<std::vector<double>> X;
    for (double v : n)
        X.push_back({v, 1.0});
    return fit_linear(X, y, {"m", "r"});
}

double LevelledFit::level(int cls) const {
    const auto it = levels.find(cls);
    return it == levels.end() ? 1.0 : it->second;
}

LevelledFit fit_levelled(const std::vector<std::vector<double>> &X, std::span<const double> y,
                         std::vector<std::string> terms, std::span<const int> classes) {
    if (!classes.empty() && classes.size() != X.size())
        throw std::invalid_argument("fit_levelled: X and classes differ in length");
    LevelledFit out;
    const std::set<int> distinct(classes.begin(), classes.end());
    out.fit = fit_linear(X, y, terms);
    if (distinct.size() < 2)
        return out;
    // Gauss-Newton on (beta, the levels of all classes but the first, whose level stays 1):
    // the residual y - level X beta is bilinear, so it converges in a few steps where
    // alternating the two least-squares problems crawls along the constant-level valley.
    const std::vector<int> cls(distinct.begin(), distinct.end());
    std::map<int, double> level;
    for (int c : cls)
        level[c] = 1.0;
    std::vector<double> beta = out.fit.coef;
    const std::size_t p = beta.size();
    std::vector<std::string> names(p + cls.size() - 1, "d");
    constexpr int max_steps = 100;
    constexpr double tolerance = 1e-12;
    std::vector<std::vector<double>> J(X.size(), std::vector<double>(names.size()));
    std::vector<double> r(X.size());
    for (int step = 0; step < max_steps; ++step) {
        for (std::size_t i = 0; i < X.size(); ++i) {
            double xb = 0;
            for (std::size_t k = 0; k < p; ++k)
                xb += X[i][k] * beta[k];
            const double l = level[classes[i]];
            r[i] = y[i] - l * xb;
            for (std::size_t k = 0; k < p; ++k)
                J[i][k] = l * X[i][k];
            for (std::size_t c = 1; c < cls.size(); ++c)
                J[i][p + c - 1] = classes[i] == cls[c] ? xb : 0.0;
        }
        const LinearFit d = fit_linear(J, r, names);
        double change = 0;
        for (std::size_t k = 0; k < p; ++k) {
            beta[k] += d.coef[k];
            change = std::max(change, std::abs(d.coef[k]) / std::max(std::abs(beta[k]), 1e-300));
        }
        for (std::size_t c = 1; c < cls.size(); ++c) {
            level[cls[c]] += d.coef[p + c - 1];
            change = std::max(change, std::abs(d.coef[p + c - 1]) / std::abs(level[cls[c]]));
        }
        if (change < tolerance)
            break;
    }
    // Normalised to a mean level of 1; the shape refitted at those levels carries the
    // standard errors (given the levels).
    double mean = 0;
    for (int c : cls)
        mean += level[c] / static_cast<double>(cls.size());
    for (int c : cls)
        out.levels[c] = level[c] / mean;
    std::vector<std::vector<double>> Xs = X;
    for (std::size_t i = 0; i < X.size(); ++i)
        for (auto &v : Xs[i])
            v *= out.levels[classes[i]];
    out.fit = fit_linear(Xs, y, terms);
    return out;
}

namespace {
std::vector<int> select(std::span<const int> v, const std::vector<std::size_t> &rows) {
    std::vector<int> out;
    if (!v.empty())
        for (std::size_t i : rows)
            out.push_back(v[i]);
    return out;
}

// The levelled fit to every row whose fold is not `held_out`: one turn of a cross-validation.
LevelledFit fit_without(const std::vector<std::vector<double>> &X, std::span<const double> y,
                        std::span<const int> fold, int held_out, std::span<const int> classes) {
    std::vector<std::vector<double>> Xt;
    std::vector<double> yt;
    std::vector<std::size_t> rows;
    for (std::size_t i = 0; i < X.size(); ++i)
        if (fold[i] != held_out) {
            Xt.push_back(X[i]);
            yt.push_back(y[i]);
            rows.push_back(i);
        }
    const std::size_t p = X.empty() ? 0 : X.front().size();
    return fit_levelled(Xt, yt, std::vector<std::string>(p, "t"), select(classes, rows));
}

int class_of(std::span<const int> classes, std::size_t i) {
    return classes.empty() ? 0 : classes[i];
}
} // namespace

CvScore cross_validate_score(const std::vector<std::vector<double>> &X, std::span<const double> y,
                             std::span<const int> groups, std::span<const int> classes) {
    std::set<int> distinct(groups.begin(), groups.end());
    std::vector<int> fold(groups.begin(), groups.end());
    if (distinct.size() < 2) {
        constexpr int folds = 5;
        for (std::size_t i = 0; i < fold.size(); ++i)
            fold[i] = static_cast<int>(i % folds);
        distinct.clear();
        for (int k = 0; k < folds; ++k)
            distinct.insert(k);
    }
    double ss = 0;
    std::size_t count = 0;
    std::vector<double> fold_mse;
    for (int g : distinct) {
        const LevelledFit f = fit_without(X, y, fold, g, classes);
        double fold_ss = 0;
        std::size_t fold_count = 0;
        for (std::size_t i = 0; i < X.size(); ++i)
            if (fold[i] == g) {
                const double e = f.predict(X[i], class_of(classes, i)) - y[i];
                fold_ss += e * e;
                ++fold_count;
            }
        ss += fold_ss;
        count += fold_count;
        if (fold_count > 0)
            fold_mse.push_back(fold_ss / static_cast<double>(fold_count));
    }
    CvScore score;
    const double mse = ss / static_cast<double>(std::max<std::size_t>(count, 1));
    score.rmse = std::sqrt(mse);
    if (fold_mse.size() >= 2 && score.rmse > 0) {
        const Summary s = summarize(fold_mse);
        double var = 0;
        for (double v : fold_mse)
            var += (v - s.avg) * (v - s.avg);
        var /= static_cast<double>(fold_mse.size() - 1);
        const double mse_se = std::sqrt(var / static_cast<double>(fold_mse.size()));
        score.rmse_se = mse_se / (2 * score.rmse);
    }
    return score;
}

double cross_validate(const std::vector<std::vector<double>> &X, std::span<const double> y,
                      std::span<const int> groups, std::span<const int> classes) {
    return cross_validate_score(X, y, groups, classes).rmse;
}

std::size_t select_term_set(std::span<const CvScore> scores, std::span<const std::size_t> sizes,
                            TermRule rule) {
    if (scores.empty() || scores.size() != sizes.size())
        throw std::invalid_argument("select_term_set: no candidate, or scores and sizes differ");
    std::size_t best = 0;
    for (std::size_t c = 1; c < scores.size(); ++c)
        if (scores[c].rmse < scores[best].rmse)
            best = c;
    if (rule == TermRule::best)
        return best;
    if (rule == TermRule::one_percent) {
        std::size_t kept = 0;
        for (std::size_t c = 0; c < scores.size(); ++c)
            if (scores[c].rmse < scores[kept].rmse * (sizes[c] < sizes[kept] ? 1.0 : 0.99))
                kept = c;
        return kept;
    }
    const double bound = scores[best].rmse + scores[best].rmse_se;
    std::size_t kept = best;
    for (std::size_t c = 0; c < scores.size(); ++c)
        if (scores[c].rmse <= bound &&
            (sizes[c] < sizes[kept] ||
             (sizes[c] == sizes[kept] && scores[c].rmse < scores[kept].rmse)))
            kept = c;
    return kept;
}

double cross_validate_runs(const std::vector<std::vector<double>> &X, std::span<const double> y,
                           std::span<const int> groups, std::span<const int> classes) {
    const std::set<int> distinct(groups.begin(), groups.end());
    if (distinct.size() < 2)
        throw std::invalid_argument("cross_validate_runs: needs at least two runs");
    double ss = 0;
    for (int g : distinct) {
        const LevelledFit f = fit_without(X, y, groups, g, classes);
        double predicted = 0, measured = 0;
        for (std::size_t i = 0; i < X.size(); ++i)
            if (groups[i] == g) {
                predicted += f.predict(X[i], class_of(classes, i));
                measured += y[i];
            }
        const double e = measured > 0 ? predicted / measured - 1.0 : 0.0;
        ss += e * e;
    }
    return std::sqrt(ss / static_cast<double>(distinct.size()));
}

std::vector<double> group_median_units(std::span<const double> y, std::span<const int> groups) {
    if (y.size() != groups.size())
        throw std::invalid_argument("group_median_units: y and groups differ in length");
    std::map<int, std::vector<double>> by_group;
    for (std::size_t i = 0; i < y.size(); ++i)
        by_group[groups[i]].push_back(y[i]);
    std::map<int, double> unit;
    for (const auto &[g, v] : by_group) {
        const double m = median(v);
        if (!(m > 0))
            throw std::invalid_argument("group_median_units: group " + std::to_string(g) +
                                        " has a median of " + std::to_string(m) +
                                        ", not a positive time");
        unit[g] = m;
    }
    std::vector<double> out;
    for (int g : groups)
        out.push_back(unit.at(g));
    return out;
}

std::vector<std::vector<double>> divided_rows(std::vector<std::vector<double>> X,
                                              std::span<const double> units) {
    if (X.size() != units.size())
        throw std::invalid_argument("divided_rows: X and units differ in length");
    for (std::size_t i = 0; i < X.size(); ++i)
        for (double &v : X[i])
            v /= units[i];
    return X;
}

RunLevel run_level(const LinearFit &f, const std::vector<std::vector<double>> &X,
                   std::span<const double> y, std::span<const int> groups) {
    if (X.size() != y.size() || y.size() != groups.size())
        throw std::invalid_argument("run_level: X, y and groups differ in length");
    std::map<int, std::pair<double, double>> sums; // group -> (measured, fitted)
    for (std::size_t i = 0; i < y.size(); ++i) {
        auto &s = sums[groups[i]];
        s.first += y[i];
        s.second += f.predict(X[i]);
    }
    RunLevel level;
    for (const auto &[g, s] : sums)
        if (s.second > 0) {
            level.groups.push_back(g);
            level.factors.push_back(s.first / s.second);
        }
    if (level.factors.empty())
        return level;
    const Summary s = summarize(level.factors);
    level.median = s.median;
    level.mean = s.avg;
    level.spread_pct = 100.0 * (s.max / s.min - 1.0);
    return level;
}

double fastest_repeat_level(const std::map<std::string, std::vector<double>> &by_configuration) {
    std::vector<double> fastest;
    for (const auto &[key, f] : by_configuration)
        if (!f.empty())
            fastest.push_back(*std::min_element(f.begin(), f.end()));
    if (fastest.empty())
        throw std::invalid_argument("fastest_repeat_level: no runs");
    return median(fastest);
}

LevelScatter &LevelScatter::operator+=(const LevelScatter &o) {
    sum_sq += o.sum_sq;
    dof += o.dof;
    runs += o.runs;
    return *this;
}

double LevelScatter::log_sd() const {
    return dof > 0 ? std::sqrt(sum_sq / dof) : 0.0;
}

LevelScatter level_scatter(const std::map<std::string, std::vector<double>> &factors_by_setup) {
    LevelScatter s;
    for (const auto &[setup, factors] : factors_by_setup) {
        if (factors.empty())
            continue;
        std::vector<double> logs;
        for (const double f : factors) {
            if (!(f > 0) || !std::isfinite(f))
                throw std::invalid_argument("level_scatter: factor " + std::to_string(f) +
                                            " of setup " + setup + " is not positive and finite");
            logs.push_back(std::log(f));
        }
        const double mean =
            std::accumulate(logs.begin(), logs.end(), 0.0) / static_cast<double>(logs.size());
        for (const double l : logs)
            s.sum_sq += (l - mean) * (l - mean);
        s.dof += static_cast<int>(logs.size()) - 1;
        s.runs += static_cast<int>(logs.size());
    }
    return s;
}

LinearFit scaled(LinearFit f, double factor) {
    for (auto &c : f.coef)
        c *= factor;
    for (auto &s : f.se)
        s *= std::abs(factor);
    for (auto &row : f.cov)
        for (auto &c : row)
            c *= factor * factor;
    return f;
}

} // namespace sphperf::model
