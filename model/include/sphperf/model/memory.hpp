#pragma once
// The memory model's counts (model/NOTES.md "Memory"), from our data structures: what one
// stored particle and one stored interaction cost. Calibration adds the fixed part; `sph` uses
// the counts alone to refuse, before it allocates, a run that cannot fit.
#include "sphperf/kernel_isa.hpp"

#include <string_view>

namespace sphperf::model {

// 10 doubles of SoA, id, kind, list offset, grid slot.
constexpr double bytes_per_particle = 10 * 8 + 8 + 1 + 4 + 8 + 4;
// The list index, the per-thread search block kept across steps (up to 2x capacity).
constexpr double bytes_per_interaction = 4 + 2 * 4 + 4;
// Cell+Sorted stores no pairs and no list offsets, but a cell-ordered copy of every particle:
// x, y, vx, vy, rho, P/rho^2, mass, fluid and remote flags (9 doubles), original index and
// cell key. The masses are there from the first Shepard filter on (with one mass the copy
// leaves them out, and the filter refreshes them).
// Where sph builds its AVX2 pair loops (sph/sorted.hpp pair_records, the same condition; sph
// checks the two agree), vx, vy, rho and P/rho^2 as a 16-byte record of floats (the pair
// terms' precision, sph PairReal) instead of the double vx and vy (since session 87) and
// P/rho^2 (since session 88; rho stays, for the Shepard filter).
#if defined(SPHPERF_AVX2_KERNELS)
constexpr double sorted_record_bytes = 4 * 4;
constexpr double sorted_copy_doubles = 6;
#else
constexpr double sorted_record_bytes = 0;
constexpr double sorted_copy_doubles = 9;
#endif
// Each rank also keeps, per sorted position, where its packed neighbours lie between its
// density and force passes (sph sweep_forces: offset and length, 4 bytes each; every rank
// sweeps since session 68, --overlap runs excepted, for which it is an upper bound by 8 bytes).
constexpr double sorted_bytes_per_particle =
    bytes_per_particle - 4 + sorted_copy_doubles * 8 + 4 + 4 + sorted_record_bytes + 2 * 4;

struct MemoryCounts {
    double per_particle, per_interaction;
};
constexpr MemoryCounts memory_counts(std::string_view grid) {
    if (grid == "sorted")
        return {sorted_bytes_per_particle, 0.0};
    return {bytes_per_particle, bytes_per_interaction};
}

} // namespace sphperf::model
