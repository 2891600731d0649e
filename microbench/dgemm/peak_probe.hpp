#pragma once
// Attainable double-precision compute ceiling: independent FMA chains kept in registers, on the
// widest vectors this build allows. Pure kernel: no threads, no timing.
#include <cstdint>
#include <string_view>

#if defined(__AVX512F__) || defined(__FMA__)
#include <immintrin.h>
#endif

namespace sphperf::probe {

// Enough independent chains to cover FMA latency x FMA ports on current cores (4 cycles x 2
// ports needs >= 8), while still fitting in the register file with the two constants.
inline constexpr int chains = 12;

#if defined(__AVX512F__)
inline constexpr int vector_bits = 512;
inline constexpr std::string_view isa = "avx512f";
#elif defined(__FMA__)
inline constexpr int vector_bits = 256;
inline constexpr std::string_view isa = "avx2+fma";
#else
inline constexpr int vector_bits = 64;
inline constexpr std::string_view isa = "scalar";
#endif
inline constexpr int lanes = vector_bits / 64;

// Flops done by fma_chains(iterations): one FMA = 2 flops per lane.
constexpr double flops(std::int64_t iterations) {
    return 2.0 * lanes * chains * static_cast<double>(iterations);
}

// Runs `iterations` rounds of `chains` independent FMAs; returns a checksum that depends on
// every chain, so the compiler cannot drop any of them. The chains converge to 1 and never
// overflow.
inline double fma_chains(std::int64_t iterations, double seed) {
    constexpr double mul = 1.0 - 1e-9, add = 1e-9;
#if defined(__AVX512F__)
    __m512d acc[chains];
    for (int c = 0; c < chains; ++c)
        acc[c] = _mm512_set1_pd(seed + c * 1e-3);
    const __m512d m = _mm512_set1_pd(mul), a = _mm512_set1_pd(add);
    for (std::int64_t it = 0; it < iterations; ++it)
        for (int c = 0; c < chains; ++c)
            acc[c] = _mm512_fmadd_pd(acc[c], m, a);
    double sum = 0;
    alignas(64) double lanes_out[8];
    for (int c = 0; c < chains; ++c) {
        _mm512_store_pd(lanes_out, acc[c]);
        for (double x : lanes_out)
            sum += x;
    }
    return sum;
#elif defined(__FMA__)
    __m256d acc[chains];
    for (int c = 0; c < chains; ++c)
        acc[c] = _mm256_set1_pd(seed + c * 1e-3);
    const __m256d m = _mm256_set1_pd(mul), a = _mm256_set1_pd(add);
    for (std::int64_t it = 0; it < iterations; ++it)
        for (int c = 0; c < chains; ++c)
            acc[c] = _mm256_fmadd_pd(acc[c], m, a);
    double sum = 0;
    alignas(32) double lanes_out[4];
    for (int c = 0; c < chains; ++c) {
        _mm256_store_pd(lanes_out, acc[c]);
        sum += lanes_out[0] + lanes_out[1] + lanes_out[2] + lanes_out[3];
    }
    return sum;
#else
    double acc[chains];
    for (int c = 0; c < chains; ++c)
        acc[c] = seed + c * 1e-3;
    for (std::int64_t it = 0; it < iterations; ++it)
        for (int c = 0; c < chains; ++c)
            acc[c] = acc[c] * mul + add;
    double sum = 0;
    for (int c = 0; c < chains; ++c)
        sum += acc[c];
    return sum;
#endif
}

} // namespace sphperf::probe
