#include "sphperf/model/hockney.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace sphperf::model {

namespace {
double weight(const MessageSample &s) {
    return 1.0 / (s.seconds * s.seconds);
}

// Weighted R^2 and residual statistics of a prediction over samples.
void score(std::span<const MessageSample> samples, auto &&predict, double &r2, double &max_rel,
           double &ssr) {
    double sw = 0, swy = 0;
    for (const auto &s : samples) {
        sw += weight(s);
        swy += weight(s) * s.seconds;
    }
    const double mean = swy / sw;
    double sst = 0;
    ssr = 0;
    max_rel = 0;
    for (const auto &s : samples) {
        const double e = predict(s.bytes) - s.seconds;
        ssr += weight(s) * e * e;
        sst += weight(s) * (s.seconds - mean) * (s.seconds - mean);
        max_rel = std::max(max_rel, std::abs(e) / s.seconds);
    }
    r2 = sst > 0 ? 1.0 - ssr / sst : (ssr == 0 ? 1.0 : 0.0);
}
} // namespace

LineFit fit_line(std::span<const MessageSample> samples) {
    if (samples.size() < 2)
        throw std::invalid_argument("a Hockney fit needs at least 2 message sizes");
    double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (const auto &s : samples) {
        if (!(s.seconds > 0) || !std::isfinite(s.seconds))
            throw std::invalid_argument("a Hockney fit needs positive, finite times");
        const double w = weight(s);
        sw += w;
        sx += w * s.bytes;
        sy += w * s.seconds;
        sxx += w * s.bytes * s.bytes;
        sxy += w * s.bytes * s.seconds;
    }
    const bool distinct = std::any_of(samples.begin(), samples.end(), [&](const auto &s) {
        return s.bytes != samples.front().bytes;
    });
    const double det = sw * sxx - sx * sx;
    if (!distinct || !(det > 0))
        throw std::invalid_argument("a Hockney fit needs at least 2 distinct message sizes");
    LineFit f;
    f.beta_s_per_byte = (sw * sxy - sx * sy) / det;
    f.alpha_s = (sy - f.beta_s_per_byte * sx) / sw;
    f.points = samples.size();
    f.first_bytes = samples.front().bytes;
    f.last_bytes = samples.back().bytes;
    score(
        samples, [&](double m) { return f.predict(m); }, f.r2, f.max_rel_residual, f.weighted_ssr);
    return f;
}

double PiecewiseFit::predict(double bytes) const {
    if (pieces.size() == 1 || bytes <= breakpoint_bytes)
        return pieces.front().predict(bytes);
    return pieces.back().predict(bytes);
}

PiecewiseFit fit_piecewise(std::span<const MessageSample> samples, std::size_t min_points,
                           double min_gain) {
    if (!std::is_sorted(samples.begin(), samples.end(),
                        [](const auto &a, const auto &b) { return a.bytes < b.bytes; }))
        throw std::invalid_argument("Hockney samples must be sorted by size");
    PiecewiseFit fit;
    fit.single = fit_line(samples);
    fit.pieces = {fit.single};

    double best_ssr = std::numeric_limits<double>::infinity();
    const std::size_t n = samples.size();
    for (std::size_t split = min_points; split + min_points <= n; ++split) {
        const LineFit lo = fit_line(samples.first(split));
        // The small piece's intercept is the latency every message pays: a split that makes it
        // negative fits noise (seen on time-shared pairs), not a Hockney model.
        if (!(lo.alpha_s > 0) || lo.beta_s_per_byte < 0)
            continue;
        // Likewise a piece whose time falls as messages grow: a few noisy latency points can
        // tilt a short small-message piece below zero (seen in CI on a 2-vCPU host).
        const LineFit hi = fit_line(samples.subspan(split));
        if (hi.beta_s_per_byte < 0)
            continue;
        const double ssr = lo.weighted_ssr + hi.weighted_ssr;
        if (ssr < best_ssr) {
            best_ssr = ssr;
            if (ssr < (1.0 - min_gain) * fit.single.weighted_ssr) {
                fit.pieces = {lo, hi};
                fit.breakpoint_bytes = samples[split - 1].bytes;
            }
        }
    }
    double ssr = 0;
    score(
        samples, [&](double m) { return fit.predict(m); }, fit.r2, fit.max_rel_residual, ssr);
    return fit;
}

} // namespace sphperf::model
