#include "sphperf/sph/gauge.hpp"

#include "sphperf/sph/sorted.hpp"
#include "sphperf/timer.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace sphperf::sph {

namespace {
// A 64-bit linear congruential generator (Knuth's MMIX constants): the same data everywhere.
struct Lcg {
    std::uint64_t state;
    double uniform() { // [0, 1)
        state = state * 6364136223846793005ULL + 1442695040888963407ULL;
        return static_cast<double>(state >> 11) * 0x1.0p-53;
    }
};
constexpr std::size_t group = 64;  // pairs per synthetic particle (about a packed neighbourhood)
constexpr double support = 3.0;    // 3h with h = 1
constexpr double step_back = 1e-4; // the continuity term's `back` (a time step)
} // namespace

GaugeData make_gauge_data(std::size_t particles, std::size_t pairs) {
    GaugeData d;
    Lcg rng{0x5eed};
    for (std::size_t i = 0; i < particles; ++i) {
        d.vx.push_back(rng.uniform() - 0.5);
        d.vy.push_back(rng.uniform() - 0.5);
        d.mass.push_back(1 + rng.uniform());
    }
    for (std::size_t q = 0; q < pairs; ++q) {
        d.index.push_back(
            static_cast<std::uint32_t>(rng.uniform() * static_cast<double>(particles)));
        // Within the support and away from 0, as a packed candidate is.
        const double r = 0.1 * support + 0.85 * support * rng.uniform();
        const double a = 2 * std::numbers::pi * rng.uniform();
        d.dx.push_back(r * std::cos(a));
        d.dy.push_back(r * std::sin(a));
    }
    return d;
}

double gauge_kernel(std::span<const double> vx, std::span<const double> vy,
                    std::span<const double> mass, std::span<const std::uint32_t> index,
                    std::span<const double> dx, std::span<const double> dy) {
    constexpr int lanes = 16; // the packed pair loops' (sorted.cpp)
    const std::size_t n = vx.size();
    double total = 0;
    for (std::size_t g = 0; g + group <= index.size(); g += group) {
        const std::size_t i = g % n; // the group's particle
        const double vxi = vx[i], vyi = vy[i];
        double sum[lanes] = {};
        for (std::size_t q = g; q < g + group; q += lanes) {
#pragma omp simd
            for (int l = 0; l < lanes; ++l) {
                const std::uint32_t j = index[q + static_cast<std::size_t>(l)];
                const double sx = dx[q + static_cast<std::size_t>(l)];
                const double sy = dy[q + static_cast<std::size_t>(l)];
                const double dvx = vxi - vx[j], dvy = vyi - vy[j];
                const double mx = sx - step_back * dvx, my = sy - step_back * dvy;
                const double r = std::sqrt(mx * mx + my * my);
                const double f = BranchFreeKernel::slope(r) / r;
                sum[l] += mass[j] * f * (dvx * mx + dvy * my);
            }
        }
        for (double s : sum)
            total += s;
    }
    return total;
}

SpeedGauge::SpeedGauge(std::size_t pairs, int repeats)
    : pairs_(pairs / group * group), repeats_(repeats), data_(make_gauge_data(particles, pairs_)) {}

double SpeedGauge::sample() {
    double seconds = 0, first_checksum = 0;
    int team = 1;
#pragma omp parallel reduction(+ : seconds)
    {
        double c = gauge_kernel(data_.vx, data_.vy, data_.mass, data_.index, data_.dx, data_.dy);
        const double t0 = thread_cpu_seconds();
        for (int k = 0; k < repeats_; ++k)
            c += gauge_kernel(data_.vx, data_.vy, data_.mass, data_.index, data_.dx, data_.dy);
        seconds += thread_cpu_seconds() - t0;
        if (omp_get_thread_num() == 0) {
            first_checksum = c;
            team = omp_get_num_threads();
        }
    }
    checksum_ = first_checksum;
    return seconds / team;
}

CoreLatencyGauge::CoreLatencyGauge(int batches)
    : batches_(std::max(batches, 1)), times_(static_cast<std::size_t>(batches_)) {}

double CoreLatencyGauge::sample() {
    constexpr double none = std::numeric_limits<double>::quiet_NaN();
    if (omp_get_max_threads() < 2)
        return none;
    line_.value.store(0);
    line_.abandoned.store(false);
    bool complete = false;
    const int trips = 1 + batches_ * round_trips_per_batch;
#pragma omp parallel
    {
        const int me = omp_get_thread_num();
        // Waits until the line holds `want`; false on the timeout or once the other gave up.
        const auto wait_for = [this](std::uint32_t want) {
            const double since = wall_seconds();
            for (std::uint32_t spins = 0;; ++spins) {
                if (line_.value.load(std::memory_order_acquire) == want)
                    return true;
                if ((spins & 63) == 63 &&
                    (line_.abandoned.load() || wall_seconds() - since > timeout_s)) {
                    line_.abandoned.store(true);
                    return false;
                }
            }
        };
        // Round trip 0 only meets the two threads (they enter the region at different times);
        // thread 0 times the others in batches, a clock read costing a good part of a round
        // trip here.
        if (me == 0) {
            bool ok = true;
            double t0 = 0;
            for (int k = 0; ok && k < trips; ++k) {
                if (k % round_trips_per_batch == 1) {
                    const double now = wall_seconds();
                    if (k > 1)
                        times_[static_cast<std::size_t>(k / round_trips_per_batch - 1)] =
                            (now - t0) / round_trips_per_batch;
                    t0 = now;
                }
                line_.value.store(static_cast<std::uint32_t>(2 * k + 1), std::memory_order_release);
                ok = wait_for(static_cast<std::uint32_t>(2 * k + 2));
            }
            if (ok)
                times_.back() = (wall_seconds() - t0) / round_trips_per_batch;
            complete = ok;
        } else if (me == 1) {
            for (int k = 0; k < trips; ++k) {
                if (!wait_for(static_cast<std::uint32_t>(2 * k + 1)))
                    break;
                line_.value.store(static_cast<std::uint32_t>(2 * k + 2), std::memory_order_release);
            }
        }
    }
    if (!complete)
        return none;
    const auto mid = times_.begin() + static_cast<std::ptrdiff_t>(times_.size() / 2);
    std::nth_element(times_.begin(), mid, times_.end());
    return *mid;
}

} // namespace sphperf::sph
