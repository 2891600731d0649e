#pragma once
// Piecewise-linear lookup shared by the model's measured curves (exchange cost by gap, compute
// profile by Froude time).
#include <utility>
#include <vector>

namespace sphperf::model {

// Linear interpolation of y over x (points sorted by x, at least one), held constant outside.
inline double interpolate(const std::vector<std::pair<double, double>> &xy, double x) {
    if (x <= xy.front().first)
        return xy.front().second;
    for (std::size_t i = 1; i < xy.size(); ++i)
        if (x <= xy[i].first) {
            const auto [x0, y0] = xy[i - 1];
            const auto [x1, y1] = xy[i];
            return x1 > x0 ? y0 + (y1 - y0) * (x - x0) / (x1 - x0) : y1;
        }
    return xy.back().second;
}

} // namespace sphperf::model
