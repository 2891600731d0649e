#pragma once
// The STREAM kernels compiled at several vector widths. Which width sustains the most bandwidth
// depends on the machine (on Zen 4 under KVM, 128-bit stores beat 512-bit ones by ~35% at one
// thread), so the benchmark measures each width the CPU supports and reports the best, rather
// than whatever width one compiler flag happened to choose.
#include <cstddef>
#include <vector>

namespace sphperf::stream {

struct KernelSet {
    int vector_bits;
    void (*copy)(const double *a, double *c, std::size_t n);
    void (*scale)(const double *c, double *b, double s, std::size_t n);
    void (*add)(const double *a, const double *b, double *c, std::size_t n);
    void (*triad)(double *a, const double *b, const double *c, double s, std::size_t n);
    // Streaming (non-temporal) stores; `a` 64-byte aligned.
    void (*triad_nt)(double *a, const double *b, const double *c, double s, std::size_t n);
};

// Widths compiled in and supported by this CPU, narrowest first.
std::vector<KernelSet> available_kernel_sets();

} // namespace sphperf::stream
