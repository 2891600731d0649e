// Compiled once per vector width (SPHPERF_STREAM_WIDTH = 128, 256, 512) with matching
// -mprefer-vector-width and ISA flags; see CMakeLists.txt.
#include "stream_width.hpp"
#include "stream_kernels.hpp"

#include <immintrin.h>

#define SPHPERF_CAT2(a, b) a##b
#define SPHPERF_CAT(a, b) SPHPERF_CAT2(a, b)
#define SPHPERF_NS SPHPERF_CAT(w, SPHPERF_STREAM_WIDTH)

namespace sphperf::stream::SPHPERF_NS {

void copy(const double *a, double *c, std::size_t n) {
    stream::copy<double>({a, n}, {c, n});
}
void scale(const double *c, double *b, double s, std::size_t n) {
    stream::scale<double>({c, n}, {b, n}, s);
}
void add(const double *a, const double *b, double *c, std::size_t n) {
    stream::add<double>({a, n}, {b, n}, {c, n});
}
void triad(double *a, const double *b, const double *c, double s, std::size_t n) {
    stream::triad<double>({a, n}, {b, n}, {c, n}, s);
}

void triad_nt(double *a, const double *b, const double *c, double s, std::size_t n) {
    std::size_t j = 0;
#if SPHPERF_STREAM_WIDTH == 512
    const __m512d vs = _mm512_set1_pd(s);
    for (; j + 8 <= n; j += 8)
        _mm512_stream_pd(a + j,
                         _mm512_fmadd_pd(vs, _mm512_loadu_pd(c + j), _mm512_loadu_pd(b + j)));
#elif SPHPERF_STREAM_WIDTH == 256
    const __m256d vs = _mm256_set1_pd(s);
    for (; j + 4 <= n; j += 4)
        _mm256_stream_pd(a + j, _mm256_add_pd(_mm256_loadu_pd(b + j),
                                              _mm256_mul_pd(vs, _mm256_loadu_pd(c + j))));
#else
    const __m128d vs = _mm_set1_pd(s);
    for (; j + 2 <= n; j += 2)
        _mm_stream_pd(a + j, _mm_add_pd(_mm_loadu_pd(b + j), _mm_mul_pd(vs, _mm_loadu_pd(c + j))));
#endif
    for (; j < n; ++j)
        a[j] = b[j] + s * c[j];
    _mm_sfence(); // streaming stores are weakly ordered: make them visible before timing stops
}

KernelSet kernel_set() {
    return {SPHPERF_STREAM_WIDTH, &copy, &scale, &add, &triad, &triad_nt};
}

} // namespace sphperf::stream::SPHPERF_NS
