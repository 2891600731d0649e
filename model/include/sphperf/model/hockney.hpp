#pragma once
// Hockney model T(M) = alpha + M beta for point-to-point messages, fitted by weighted least
// squares (weights 1/T^2, i.e. relative residuals, so 1-byte latencies count as much as 16 MiB
// transfers), and a two-piece version with a detected breakpoint for MPI's eager/rendezvous switch.
#include <cstddef>
#include <span>
#include <vector>

namespace sphperf::model {

struct MessageSample {
    double bytes;
    double seconds; // one-way time
};

struct LineFit {
    double alpha_s = 0;
    double beta_s_per_byte = 0;
    double r2 = 0;               // weighted coefficient of determination
    double max_rel_residual = 0; // max |fit - T| / T
    double weighted_ssr = 0;     // sum of squared relative residuals
    std::size_t points = 0;
    double first_bytes = 0;
    double last_bytes = 0;

    double predict(double bytes) const { return alpha_s + beta_s_per_byte * bytes; }
};

// Needs at least 2 samples with distinct sizes and positive times.
LineFit fit_line(std::span<const MessageSample> samples);

struct PiecewiseFit {
    LineFit single;              // one line over everything, for comparison
    std::vector<LineFit> pieces; // 1 piece (no break found) or 2 (small, large)
    double breakpoint_bytes = 0; // largest size of the small-message piece; 0 when no break
    double r2 = 0;               // weighted R^2 of the whole model
    double max_rel_residual = 0;

    // Small-message latency and large-message inverse bandwidth.
    double alpha_s() const { return pieces.front().alpha_s; }
    double beta_s_per_byte() const { return pieces.back().beta_s_per_byte; }
    double predict(double bytes) const;
};

// Samples sorted by size. Every split leaving >= min_points on each side whose small piece has a
// positive latency and whose pieces both have a slope >= 0 is tried and the one with the least
// total squared relative residual is kept when it beats the single line by more than `min_gain`
// (fractional reduction of the residual).
PiecewiseFit fit_piecewise(std::span<const MessageSample> samples, std::size_t min_points = 3,
                           double min_gain = 0.5);

} // namespace sphperf::model
