#pragma once
// Quintic spline kernel of support 3h in 2D (thesis Eq. 2.1): pure functions of the distance.
#include <numbers>

namespace sphperf::sph {

struct QuinticKernel {
    double h;       // smoothing length
    double alpha_d; // 7 / (478 pi h^2): normalises W over the plane

    explicit constexpr QuinticKernel(double smoothing_length)
        : h(smoothing_length), alpha_d(7.0 / (478.0 * std::numbers::pi * h * h)) {}

    static constexpr double support_factor = 3.0; // W = 0 beyond R = r/h = 3
    constexpr double support() const { return support_factor * h; }

    static constexpr double pow5(double v) { return v * v * v * v * v; }
    static constexpr double pow4(double v) { return v * v * v * v; }

    // W(r)
    constexpr double value(double r) const {
        const double q = r / h;
        double w = 0;
        if (q < 3)
            w += pow5(3 - q);
        if (q < 2)
            w -= 6 * pow5(2 - q);
        if (q < 1)
            w += 15 * pow5(1 - q);
        return alpha_d * w;
    }

    // dW/dr (negative inside the support); the gradient is dW/dr * (r_i - r_j) / r.
    constexpr double derivative(double r) const {
        const double q = r / h;
        double d = 0;
        if (q < 3)
            d -= 5 * pow4(3 - q);
        if (q < 2)
            d += 30 * pow4(2 - q);
        if (q < 1)
            d -= 75 * pow4(1 - q);
        return alpha_d * d / h;
    }
};

} // namespace sphperf::sph
