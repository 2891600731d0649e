#pragma once
// Small descriptive statistics used by every benchmark.
#include <cstddef>
#include <span>
#include <vector>

namespace sphperf {

struct Summary {
    double min = 0.0;
    double avg = 0.0;
    double max = 0.0;
    double median = 0.0;
    std::size_t count = 0;
};

Summary summarize(std::span<const double> values);
double median(std::span<const double> values);

struct Interval {
    double lo = 0.0;
    double hi = 0.0;
};

// Distribution-free 95% confidence interval of the median from order statistics
// (normal approximation of the binomial). Needs at least 6 values; fewer give [min, max].
Interval median_ci95(std::span<const double> values);

} // namespace sphperf
