#pragma once
// Spot check of a row-major product C = A B against the naive dot product, with a forward
// error bound, so a wrong BLAS (or a wrong call) cannot report a figure.
#include <cmath>
#include <cstddef>
#include <limits>
#include <random>
#include <span>

namespace sphperf::gemm {

struct SpotCheck {
    bool ok = true;
    std::size_t checked = 0;
    double worst_ratio = 0; // |error| / bound, must stay <= 1
};

// C is m x q, A is m x k, B is k x q, all row-major and dense.
inline SpotCheck spot_check(std::span<const double> a, std::span<const double> b,
                            std::span<const double> c, std::size_t m, std::size_t k, std::size_t q,
                            std::size_t samples, unsigned seed) {
    SpotCheck r;
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<std::size_t> row(0, m - 1), col(0, q - 1);
    constexpr double eps = std::numeric_limits<double>::epsilon();
    for (std::size_t s = 0; s < samples; ++s) {
        const std::size_t i = row(rng), j = col(rng);
        double exact = 0, magnitude = 0;
        for (std::size_t l = 0; l < k; ++l) {
            exact += a[i * k + l] * b[l * q + j];
            magnitude += std::abs(a[i * k + l] * b[l * q + j]);
        }
        // Both sums carry at most k rounding errors each (standard dot-product bound), x2 margin.
        const double bound = 2.0 * 2.0 * static_cast<double>(k) * eps * magnitude + 1e-300;
        const double ratio = std::abs(c[i * q + j] - exact) / bound;
        r.worst_ratio = std::max(r.worst_ratio, ratio);
        if (!(ratio <= 1.0))
            r.ok = false;
        ++r.checked;
    }
    return r;
}

} // namespace sphperf::gemm
