#pragma once
// McCalpin's STREAM kernels as pure functions on spans (no threads, no timing), with the byte
// accounting of the reference STREAM as data and its validation replayed on scalars.
#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <string_view>

namespace sphperf::stream {

enum class Kernel { copy, scale, add, triad };

struct KernelSpec {
    Kernel kernel;
    std::string_view name;
    int arrays_read;
    int arrays_written;
};

// STREAM counts each array once per element: 16 B/element for copy and scale, 24 B for add and
// triad (write-allocate traffic is deliberately not counted, as in the reference).
inline constexpr std::array<KernelSpec, 4> kernels{{{Kernel::copy, "copy", 1, 1},
                                                    {Kernel::scale, "scale", 1, 1},
                                                    {Kernel::add, "add", 2, 1},
                                                    {Kernel::triad, "triad", 2, 1}}};

template <class T> constexpr double bytes_moved(const KernelSpec &k, std::size_t n) {
    return static_cast<double>(k.arrays_read + k.arrays_written) * sizeof(T) *
           static_cast<double>(n);
}

// The same initial values and scalar as the reference STREAM.
template <class T> struct Initial {
    static constexpr T a = 1;
    static constexpr T b = 2;
    static constexpr T c = 0;
    static constexpr T scalar = 3;
};

template <class T> void copy(std::span<const T> a, std::span<T> c) {
    for (std::size_t j = 0; j < c.size(); ++j)
        c[j] = a[j];
}
template <class T> void scale(std::span<const T> c, std::span<T> b, T s) {
    for (std::size_t j = 0; j < b.size(); ++j)
        b[j] = s * c[j];
}
template <class T> void add(std::span<const T> a, std::span<const T> b, std::span<T> c) {
    for (std::size_t j = 0; j < c.size(); ++j)
        c[j] = a[j] + b[j];
}
template <class T> void triad(std::span<T> a, std::span<const T> b, std::span<const T> c, T s) {
    for (std::size_t j = 0; j < a.size(); ++j)
        a[j] = b[j] + s * c[j];
}

struct Validation {
    bool ok = false;
    std::array<double, 3> rel_error{}; // a, b, c: average |x - expected| / |expected|
};

// Relative tolerance of the reference STREAM for double.
inline constexpr double validation_epsilon = 1.e-13;

// Expected values after `iterations` passes of copy, scale, add, triad from Initial<T>, with the
// reference's initial doubling of a.
template <class T> std::array<T, 3> expected_values(int iterations) {
    T aj = Initial<T>::a, bj = Initial<T>::b, cj = Initial<T>::c;
    const T s = Initial<T>::scalar;
    aj = 2 * aj;
    for (int k = 0; k < iterations; ++k) {
        cj = aj;
        bj = s * cj;
        cj = aj + bj;
        aj = bj + s * cj;
    }
    return {aj, bj, cj};
}

// Sums of |x - expected| over each array: the reference's check, split so that each thread
// can sum its own part.
template <class T>
std::array<double, 3> abs_error_sums(std::span<const T> a, std::span<const T> b,
                                     std::span<const T> c, const std::array<T, 3> &expected) {
    // Eight independent partial sums per array: one chain of dependent adds ran at a third of
    // the memory's speed and took longer than the timed kernels (a tolerance check, so the
    // order of the additions does not matter).
    constexpr std::size_t lanes = 8;
    const std::array<std::span<const T>, 3> arrays{a, b, c};
    std::array<double, 3> sums{};
    for (std::size_t k = 0; k < 3; ++k) {
        const std::span<const T> x = arrays[k];
        const auto e = static_cast<double>(expected[k]);
        std::array<double, lanes> part{};
        const std::size_t whole = x.size() - x.size() % lanes;
        for (std::size_t i = 0; i < whole; i += lanes)
            for (std::size_t l = 0; l < lanes; ++l)
                part[l] += std::abs(static_cast<double>(x[i + l]) - e);
        for (std::size_t i = whole; i < x.size(); ++i)
            part[0] += std::abs(static_cast<double>(x[i]) - e);
        for (double p : part)
            sums[k] += p;
    }
    return sums;
}

// The verdict from those sums over arrays of n elements: the average relative error of each.
template <class T>
Validation validation_from_sums(const std::array<double, 3> &sums, std::size_t n,
                                const std::array<T, 3> &expected) {
    Validation v;
    v.ok = n > 0;
    for (std::size_t k = 0; k < 3; ++k) {
        v.rel_error[k] =
            sums[k] / static_cast<double>(n) / std::abs(static_cast<double>(expected[k]));
        if (!(v.rel_error[k] <= validation_epsilon))
            v.ok = false;
    }
    return v;
}

template <class T>
Validation validate(std::span<const T> a, std::span<const T> b, std::span<const T> c,
                    const std::array<T, 3> &expected) {
    return validation_from_sums<T>(abs_error_sums<T>(a, b, c, expected), a.size(), expected);
}

// Half-open range of elements owned by `thread` of `threads`, boundaries on 8-element (64-byte)
// multiples so streaming stores stay aligned and first touch matches the kernels' partition.
struct Range {
    std::size_t begin, end;
};
inline Range chunk(std::size_t n, int threads, int thread) {
    constexpr std::size_t align = 8;
    const std::size_t blocks = (n + align - 1) / align;
    const auto t = static_cast<std::size_t>(thread), nt = static_cast<std::size_t>(threads);
    const std::size_t b0 = blocks * t / nt, b1 = blocks * (t + 1) / nt;
    return {std::min(n, b0 * align), std::min(n, b1 * align)};
}

} // namespace sphperf::stream
