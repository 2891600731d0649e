#pragma once
// Kick-drift-kick leapfrog with density staggered like position: velocity is kicked by half
// steps, position and density advance by whole steps with the half-step velocity. Advancing
// density together with velocity instead would integrate the acoustic (rho, v) oscillator with
// forward Euler, which is unstable at any dt. Wall particles keep position and velocity; their
// density evolves.
#include "sphperf/sph/particles.hpp"

namespace sphperf::sph {

inline void half_kick(Particles &p, double dt) {
    const std::size_t owned = p.owned();
    const double h = 0.5 * dt;
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < owned; ++i) {
        p.vx[i] += h * p.ax[i];
        p.vy[i] += h * p.ay[i];
    }
}

inline void advance_density(Particles &p, double dt) {
    const std::size_t owned = p.owned();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < owned; ++i)
        p.rho[i] += dt * p.drho[i];
}

inline void drift(Particles &p, double dt) {
    const std::size_t fluid = p.fluid();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < fluid; ++i) {
        p.x[i] += dt * p.vx[i];
        p.y[i] += dt * p.vy[i];
    }
}

} // namespace sphperf::sph
