#pragma once
// The weakly compressible SPH equations as pure pair kernels, and the drivers that loop over
// particles and their neighbours. Nothing here knows about grids, ranks or threads' origins.
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/neighbours.hpp"
#include "sphperf/sph/particles.hpp"

namespace sphperf::sph {

// Contribution of neighbour j to particle i (Monaghan 1994), with grad W_ij = dW/dr (r_i - r_j)/r:
//   drho_i/dt += m_j (v_i - v_j) . grad W_ij                                   (continuity)
//   dv_i/dt   -= m_j (P_i / rho_i^2 + P_j / rho_j^2 + Pi_ij) grad W_ij          (momentum)
// with Monaghan's artificial viscosity Pi_ij for approaching pairs.
struct PairInput {
    double dx, dy, r; // r_i - r_j and |r_i - r_j|, 0 < r < 3h
    double dvx, dvy;  // v_i - v_j
    double rho_i, rho_j, p_i, p_j, m_j;
};
struct Acceleration {
    double ax, ay;
};

inline double continuity_term(const PairInput &in, const QuinticKernel &k) {
    const double f = k.derivative(in.r) / in.r;
    return in.m_j * f * (in.dvx * in.dx + in.dvy * in.dy);
}

inline Acceleration momentum_term(const PairInput &in, const QuinticKernel &k, double c0,
                                  double alpha) {
    const double f = k.derivative(in.r) / in.r;
    const double vdotr = in.dvx * in.dx + in.dvy * in.dy;
    double visc = 0;
    if (vdotr < 0) {
        constexpr double eta2_factor = 0.01; // keeps mu finite for coincident particles
        const double mu = k.h * vdotr / (in.r * in.r + eta2_factor * k.h * k.h);
        visc = -alpha * c0 * mu / (0.5 * (in.rho_i + in.rho_j));
    }
    const double coef =
        in.m_j * (in.p_i / (in.rho_i * in.rho_i) + in.p_j / (in.rho_j * in.rho_j) + visc);
    return {-coef * f * in.dx, -coef * f * in.dy};
}

// Pressure from density for every particle (Tait equation).
void equation_of_state(Particles &p, const Physics &phys);

// Accelerations and density rates of the owned particles from their neighbour lists. Wall
// particles of the fixed boundary get a density rate only (they do not move).
// Density rates of the owned particles (fluid and fixed wall particles).
void continuity(Particles &p, const NeighbourList &nl, const Physics &phys);

// Accelerations of the owned fluid particles (wall particles do not move).
void momentum(Particles &p, const NeighbourList &nl, const Physics &phys);

// Shepard filter: rho_i = sum_j m_j W_ij / sum_j (m_j / rho_j) W_ij over i and its neighbours.
void shepard_filter(Particles &p, const NeighbourList &nl, const Physics &phys);

} // namespace sphperf::sph
