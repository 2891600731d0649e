#include "gemm_check.hpp"
#include "peak_probe.hpp"

#include <gtest/gtest.h>

#include <cmath>

using sphperf::gemm::spot_check;

namespace {
std::vector<double> naive(const std::vector<double> &a, const std::vector<double> &b, std::size_t m,
                          std::size_t k, std::size_t q) {
    std::vector<double> c(m * q, 0.0);
    for (std::size_t i = 0; i < m; ++i)
        for (std::size_t l = 0; l < k; ++l)
            for (std::size_t j = 0; j < q; ++j)
                c[i * q + j] += a[i * k + l] * b[l * q + j];
    return c;
}
} // namespace

TEST(GemmCheck, AcceptsACorrectProductAndRejectsAWrongOne) {
    constexpr std::size_t m = 17, k = 23, q = 11;
    std::vector<double> a(m * k), b(k * q);
    for (std::size_t i = 0; i < a.size(); ++i)
        a[i] = std::sin(0.3 * i);
    for (std::size_t i = 0; i < b.size(); ++i)
        b[i] = std::cos(0.7 * i);
    auto c = naive(a, b, m, k, q);
    EXPECT_TRUE(spot_check(a, b, c, m, k, q, m * q * 4, 1).ok);
    // A transposed B (a classic row/column-major slip) must fail.
    for (auto &x : c)
        x = 0;
    for (std::size_t i = 0; i < m; ++i)
        for (std::size_t j = 0; j < q; ++j)
            for (std::size_t l = 0; l < k; ++l)
                c[i * q + j] += a[i * k + l] * b[(j * k + l) % (k * q)];
    EXPECT_FALSE(spot_check(a, b, c, m, k, q, 64, 1).ok);
    // So must a single wrong element when it is sampled.
    c = naive(a, b, m, k, q);
    c[5 * q + 3] *= 1.0 + 1e-9;
    EXPECT_FALSE(spot_check(a, b, c, m, k, q, m * q * 8, 2).ok);
}

TEST(PeakProbe, FlopCountAndChecksum) {
    namespace p = sphperf::probe;
    EXPECT_DOUBLE_EQ(p::flops(10), 2.0 * p::lanes * p::chains * 10);
    // Chains converge to 1 from their seeds: the checksum is finite and near lanes*chains.
    const double sum = p::fma_chains(1 << 16, 1.0);
    EXPECT_TRUE(std::isfinite(sum));
    EXPECT_NEAR(sum, p::lanes * p::chains * 1.0, 0.01 * p::lanes * p::chains);
    EXPECT_NE(p::fma_chains(10, 1.0), p::fma_chains(10, 2.0));
}
