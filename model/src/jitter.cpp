#include "sphperf/model/jitter.hpp"

#include "sphperf/stats.hpp"

#include <gsl/gsl_cdf.h>
#include <gsl/gsl_errno.h>
#include <gsl/gsl_integration.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <vector>

namespace sphperf::model {

namespace {
struct Normals {
    std::vector<double> mean, sd;
};
// 1 - P(max <= x) over the random variables: the integrand of E[max] above its lower bound.
double tail(double x, void *p) {
    const auto &n = *static_cast<const Normals *>(p);
    double all_below = 1;
    for (std::size_t r = 0; r < n.mean.size(); ++r)
        all_below *= gsl_cdf_ugaussian_P((x - n.mean[r]) / n.sd[r]);
    return 1 - all_below;
}
} // namespace

double expected_max(std::span<const double> mean, std::span<const double> sd) {
    if (mean.empty() || mean.size() != sd.size())
        throw std::invalid_argument("expected_max: needs one sd per mean, at least one");
    // Lower bound: the largest constant, or where every variable is almost surely above.
    constexpr double reach = 8; // standard deviations: P(Z > 8) ~ 6e-16
    double constant = -std::numeric_limits<double>::infinity();
    Normals random;
    for (std::size_t r = 0; r < mean.size(); ++r) {
        if (!std::isfinite(mean[r]) || !std::isfinite(sd[r]) || sd[r] < 0)
            throw std::invalid_argument("expected_max: non-finite mean or negative sd");
        if (sd[r] == 0)
            constant = std::max(constant, mean[r]);
        else {
            random.mean.push_back(mean[r]);
            random.sd.push_back(sd[r]);
        }
    }
    if (random.mean.empty())
        return constant;
    double lo = constant, hi = constant;
    for (std::size_t r = 0; r < random.mean.size(); ++r) {
        lo = std::max(lo, random.mean[r] - reach * random.sd[r]);
        hi = std::max(hi, random.mean[r] + reach * random.sd[r]);
    }
    // A variable almost surely below the bound never sets the maximum.
    Normals live;
    for (std::size_t r = 0; r < random.mean.size(); ++r)
        if (random.mean[r] + reach * random.sd[r] > lo) {
            live.mean.push_back(random.mean[r]);
            live.sd.push_back(random.sd[r]);
        }
    if (live.mean.empty() || hi <= lo)
        return lo;
    if (live.mean.size() == 1 && lo <= live.mean[0] - reach * live.sd[0])
        return live.mean[0]; // one variable and nothing above it: exactly its mean
    gsl_set_error_handler_off();
    constexpr std::size_t limit = 200;
    std::unique_ptr<gsl_integration_workspace, decltype(&gsl_integration_workspace_free)> work(
        gsl_integration_workspace_alloc(limit), gsl_integration_workspace_free);
    gsl_function f{&tail, &live};
    double area = 0, error = 0;
    const int status = gsl_integration_qag(&f, lo, hi, 0, 1e-10, limit, GSL_INTEG_GAUSS21,
                                           work.get(), &area, &error);
    if (status != GSL_SUCCESS && error > 1e-6 * (hi - lo))
        throw std::runtime_error(std::string("expected_max: integration failed: ") +
                                 gsl_strerror(status));
    return lo + area;
}

std::string_view to_string(JitterForm form) {
    return form == JitterForm::sqrt ? "sqrt" : "proportional";
}

double modelled_wait(std::span<const BusyInterval> intervals, Jitter j) {
    double wait = 0;
    std::vector<double> mean, sd;
    for (const auto &iv : intervals) {
        mean.clear();
        sd.clear();
        for (std::size_t k = 0; k < iv.compute_s.size(); ++k) {
            mean.push_back(iv.compute_s[k] + iv.comm_s.at(k));
            sd.push_back(jitter_sd(j, iv.compute_s[k]));
        }
        const double step = expected_max(mean, sd);
        for (double m : mean)
            wait += iv.steps * (step - m);
    }
    return wait;
}

double fit_jitter(std::span<const BusyInterval> intervals, double measured_wait_s,
                  JitterForm form) {
    // The modelled wait grows with k: bisection.
    const auto wait = [&](double k) { return modelled_wait(intervals, Jitter{form, k}); };
    if (wait(0) >= measured_wait_s)
        return 0;
    if (wait(jitter_k_max) <= measured_wait_s)
        return jitter_k_max;
    double lo = 0, hi = jitter_k_max;
    while (hi - lo > 1e-9)
        (wait(0.5 * (lo + hi)) < measured_wait_s ? lo : hi) = 0.5 * (lo + hi);
    return 0.5 * (lo + hi);
}

double jitter_cv_rms(std::span<const WaitRun> runs, std::span<const double> k, JitterForm form) {
    if (k.size() != runs.size())
        throw std::invalid_argument("jitter_cv_rms: needs one k per run");
    if (runs.size() < 3)
        return std::numeric_limits<double>::quiet_NaN();
    double sum = 0;
    for (std::size_t i = 0; i < runs.size(); ++i) {
        std::vector<double> others;
        for (std::size_t o = 0; o < runs.size(); ++o)
            if (o != i)
                others.push_back(k[o]);
        const double predicted =
            modelled_wait(runs[i].busy, Jitter{form, summarize(others).median});
        const double e = (predicted - runs[i].measured_wait_s) / runs[i].measured_time_s;
        sum += e * e;
    }
    return std::sqrt(sum / static_cast<double>(runs.size()));
}

} // namespace sphperf::model
