#pragma once
// Kick-drift-kick leapfrog with density staggered like position: velocity is kicked by half
// steps, position and density advance by whole steps with the half-step velocity. Advancing
// density together with velocity instead would integrate the acoustic (rho, v) oscillator with
// forward Euler, which is unstable at any dt. Wall particles keep position and velocity; their
// density evolves.
#include "sphperf/sph/particles.hpp"

#include <algorithm>
#include <omp.h>
#include <span>
#include <utility>

namespace sphperf::sph {

// The calling thread's share of [0, n) as `schedule(static)` deals it out (the first n % T
// threads one more), so that a loop over part of the range keeps the partition of the loops
// over all of it.
inline std::pair<std::size_t, std::size_t> static_share(std::size_t n) {
    const auto threads = static_cast<std::size_t>(omp_get_num_threads());
    const auto t = static_cast<std::size_t>(omp_get_thread_num());
    const std::size_t q = n / threads, r = n % threads;
    const std::size_t begin = t < r ? t * (q + 1) : t * q + r;
    return {begin, begin + (t < r ? q + 1 : q)};
}

// The calling thread's fluid particles: [split[t], split[t + 1]) when the grid gave one range
// per thread of this team over the whole fluid (CellSorted::fluid_split), else `fallback`.
inline std::pair<std::size_t, std::size_t>
fluid_share(const Particles &p, std::span<const std::size_t> split,
            std::pair<std::size_t, std::size_t> fallback) {
    const auto t = static_cast<std::size_t>(omp_get_thread_num());
    if (split.size() == static_cast<std::size_t>(omp_get_num_threads()) + 1 &&
        split.back() == p.fluid())
        return {split[t], split[t + 1]};
    return fallback;
}

// Walls are owned but never accelerate (their acceleration is 0): only the fluid is kicked.
// Kicking a wall rewrote its unchanged velocity, a line the grid's copy then fetched again on
// the other core. Without a split, each thread within its static share of the owned particles,
// as the stored-list grids' passes write the accelerations.
inline void half_kick(Particles &p, double dt, std::span<const std::size_t> split = {}) {
    const std::size_t owned = p.owned(), fluid = p.fluid();
    const double h = 0.5 * dt;
#pragma omp parallel
    {
        const auto [share_begin, share_end] = static_share(owned);
        const auto [begin, end] =
            fluid_share(p, split, {std::min(share_begin, fluid), std::min(share_end, fluid)});
        for (std::size_t i = begin; i < end; ++i) {
            p.vx[i] += h * p.ax[i];
            p.vy[i] += h * p.ay[i];
        }
    }
}

inline void advance_density(Particles &p, double dt) {
    const std::size_t owned = p.owned();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < owned; ++i)
        p.rho[i] += dt * p.drho[i];
}

inline void drift(Particles &p, double dt, std::span<const std::size_t> split = {}) {
#pragma omp parallel
    {
        const auto [begin, end] = fluid_share(p, split, static_share(p.fluid()));
        for (std::size_t i = begin; i < end; ++i) {
            p.x[i] += dt * p.vx[i];
            p.y[i] += dt * p.vy[i];
        }
    }
}

} // namespace sphperf::sph
