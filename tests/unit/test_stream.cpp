#include "stream_kernels.hpp"
#include "stream_width.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace st = sphperf::stream;

TEST(Stream, ByteAccountingFollowsReferenceStream) {
    constexpr std::size_t n = 1000;
    const double expected[] = {16.0 * n, 16.0 * n, 24.0 * n, 24.0 * n};
    for (std::size_t k = 0; k < st::kernels.size(); ++k)
        EXPECT_DOUBLE_EQ(st::bytes_moved<double>(st::kernels[k], n), expected[k])
            << st::kernels[k].name;
    EXPECT_DOUBLE_EQ(st::bytes_moved<float>(st::kernels[3], n), 12.0 * n);
}

namespace {
struct Arrays {
    std::vector<double> a, b, c;
    explicit Arrays(std::size_t n)
        : a(n, 2 * st::Initial<double>::a), b(n, st::Initial<double>::b),
          c(n, st::Initial<double>::c) {}
    void iterate(int times) {
        const double s = st::Initial<double>::scalar;
        for (int k = 0; k < times; ++k) {
            st::copy<double>(a, c);
            st::scale<double>(c, b, s);
            st::add<double>(a, b, c);
            st::triad<double>(a, b, c, s);
        }
    }
};
} // namespace

TEST(Stream, KernelsMatchTheScalarReplay) {
    Arrays x(1003);
    x.iterate(5);
    const auto v = st::validate<double>(x.a, x.b, x.c, st::expected_values<double>(5));
    EXPECT_TRUE(v.ok);
    for (double e : v.rel_error)
        EXPECT_EQ(e, 0.0);
}

TEST(Stream, ValidationCatchesOneWrongElement) {
    Arrays x(1000);
    x.iterate(3);
    x.b[517] += 1.0;
    const auto v = st::validate<double>(x.a, x.b, x.c, st::expected_values<double>(3));
    EXPECT_FALSE(v.ok);
    EXPECT_GT(v.rel_error[1], st::validation_epsilon);
    EXPECT_EQ(v.rel_error[0], 0.0);
}

// The sums run in eight lanes with a scalar tail: an error in the last few elements of an
// array whose length is not a multiple of eight counts as much as one in the lanes.
TEST(Stream, ValidationCatchesAWrongElementInTheTail) {
    Arrays x(1005);
    x.iterate(3);
    const auto expected = st::expected_values<double>(3);
    x.a[1004] += 2.0;
    const auto tail = st::validate<double>(x.a, x.b, x.c, expected);
    x.a[1004] -= 2.0;
    x.a[3] += 2.0;
    const auto lane = st::validate<double>(x.a, x.b, x.c, expected);
    EXPECT_FALSE(tail.ok);
    EXPECT_FALSE(lane.ok);
    EXPECT_DOUBLE_EQ(tail.rel_error[0], lane.rel_error[0]);
    EXPECT_DOUBLE_EQ(tail.rel_error[0], 2.0 / 1005 / std::abs(expected[0]));
}

// The threads of the benchmark each sum their own part: the parts' sums give the whole check,
// and a wrong element in any part fails it.
TEST(Stream, ValidationSummedInPartsMatchesTheWhole) {
    Arrays x(1000);
    x.iterate(3);
    x.c[900] -= 0.25;
    const auto expected = st::expected_values<double>(3);
    const auto whole = st::validate<double>(x.a, x.b, x.c, expected);
    std::array<double, 3> sums{};
    for (int t = 0; t < 3; ++t) {
        const auto rg = st::chunk(x.a.size(), 3, t);
        const auto part = [&](const std::vector<double> &v) {
            return std::span<const double>(v.data() + rg.begin, rg.end - rg.begin);
        };
        const auto s = st::abs_error_sums<double>(part(x.a), part(x.b), part(x.c), expected);
        for (std::size_t k = 0; k < 3; ++k)
            sums[k] += s[k];
    }
    const auto parts = st::validation_from_sums<double>(sums, x.a.size(), expected);
    EXPECT_FALSE(parts.ok);
    EXPECT_EQ(parts.ok, whole.ok);
    for (std::size_t k = 0; k < 3; ++k)
        EXPECT_DOUBLE_EQ(parts.rel_error[k], whole.rel_error[k]) << k;
    EXPECT_GT(parts.rel_error[2], st::validation_epsilon);
    EXPECT_FALSE(st::validation_from_sums<double>({0, 0, 0}, 0, expected).ok); // no elements
}

TEST(Stream, ValidationCatchesAWrongIterationCount) {
    Arrays x(100);
    x.iterate(4);
    EXPECT_FALSE(st::validate<double>(x.a, x.b, x.c, st::expected_values<double>(3)).ok);
}

TEST(Stream, EveryVectorWidthComputesTheSameKernels) {
    constexpr std::size_t n = 1029; // not a multiple of any vector width: exercises the tails
    std::vector<double> b(n), c(n), ref(n);
    for (std::size_t j = 0; j < n; ++j) {
        b[j] = 0.5 * j;
        c[j] = 1.0 / (j + 1);
    }
    st::triad<double>(ref, b, c, 3.0);
    const auto sets = st::available_kernel_sets();
    ASSERT_FALSE(sets.empty());
    EXPECT_EQ(sets.front().vector_bits, 128);
    for (const auto &ks : sets) {
        alignas(64) static double a[n];
        std::fill(a, a + n, 0.0);
        ks.triad_nt(a, b.data(), c.data(), 3.0, n);
        for (std::size_t j = 0; j < n; ++j)
            ASSERT_DOUBLE_EQ(a[j], ref[j]) << ks.vector_bits << " bits, nt, j=" << j;
        std::fill(a, a + n, 0.0);
        ks.triad(a, b.data(), c.data(), 3.0, n);
        for (std::size_t j = 0; j < n; ++j)
            ASSERT_DOUBLE_EQ(a[j], ref[j]) << ks.vector_bits << " bits, j=" << j;
        std::vector<double> x(n);
        ks.copy(b.data(), x.data(), n);
        EXPECT_EQ(x, b);
        ks.scale(b.data(), x.data(), 2.0, n);
        EXPECT_DOUBLE_EQ(x[n - 1], 2.0 * b[n - 1]);
        ks.add(b.data(), c.data(), x.data(), n);
        EXPECT_DOUBLE_EQ(x[7], b[7] + c[7]);
    }
}

TEST(Stream, ChunksPartitionTheArrayOnAlignedBoundaries) {
    for (std::size_t n : {1ul, 7ul, 64ul, 1000ul, 1001ul})
        for (int threads = 1; threads <= 5; ++threads) {
            std::size_t next = 0;
            for (int t = 0; t < threads; ++t) {
                const auto r = st::chunk(n, threads, t);
                EXPECT_EQ(r.begin, next);
                EXPECT_TRUE(r.begin % 8 == 0 || r.begin == n);
                next = r.end;
            }
            EXPECT_EQ(next, n);
        }
}
