#include "sphperf/stats.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace sphperf {

double median(std::span<const double> values) {
    if (values.empty())
        throw std::invalid_argument("median of an empty sample");
    std::vector<double> v(values.begin(), values.end());
    const std::size_t mid = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
    const double upper = v[mid];
    if (v.size() % 2 == 1)
        return upper;
    const double lower = *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid));
    return 0.5 * (lower + upper);
}

Summary summarize(std::span<const double> values) {
    if (values.empty())
        throw std::invalid_argument("summary of an empty sample");
    Summary s;
    s.count = values.size();
    const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
    s.min = *lo;
    s.max = *hi;
    s.avg = std::accumulate(values.begin(), values.end(), 0.0) / static_cast<double>(s.count);
    s.median = median(values);
    return s;
}

Interval median_ci95(std::span<const double> values) {
    if (values.empty())
        throw std::invalid_argument("confidence interval of an empty sample");
    std::vector<double> v(values.begin(), values.end());
    std::sort(v.begin(), v.end());
    const double n = static_cast<double>(v.size());
    constexpr double z95 = 1.959963984540054;
    if (v.size() < 6)
        return {v.front(), v.back()};
    // 1-based ranks of the order statistics bounding the median (Conover, normal approx.).
    const double half_width = z95 * std::sqrt(n) / 2.0;
    const auto lo_rank = static_cast<std::ptrdiff_t>(std::floor(n / 2.0 - half_width));
    const auto hi_rank = static_cast<std::ptrdiff_t>(std::ceil(1.0 + n / 2.0 + half_width));
    const auto last = static_cast<std::ptrdiff_t>(v.size());
    return {v[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(lo_rank, 1, last) - 1)],
            v[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(hi_rank, 1, last) - 1)]};
}

} // namespace sphperf
