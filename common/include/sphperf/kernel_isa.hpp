#pragma once
// The instruction set of Cell+Sorted's hand-written kernels (the candidate packing and the pair
// loops, sph/src/sorted.cpp), in one place: sph reads it, and so does the model's memory count
// (the AVX2 pair loops keep a 16-byte record per sorted particle more). AVX2 + FMA where the
// build has no AVX-512, or where CMake's SPHPERF_KERNELS chose avx2 on a CPU that has it
// (SPHPERF_PREFER_AVX2_KERNELS: on this VM's AMD Zen 4 host the AVX2 kernels took 0.52-0.59 of
// the AVX-512 ones' time, sph/NOTES.md, session 70); else AVX-512 where the build has it; else
// the portable loops. Preprocessor names, since they choose which intrinsics compile.
#if defined(__AVX2__) && defined(__FMA__) &&                                                       \
    (defined(SPHPERF_PREFER_AVX2_KERNELS) || !(defined(__AVX512F__) && defined(__AVX512VL__)))
#define SPHPERF_AVX2_KERNELS 1
#elif defined(__AVX512F__) && defined(__AVX512VL__)
#define SPHPERF_AVX512_KERNELS 1
#endif
