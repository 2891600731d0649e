#pragma once
// The weakly compressible SPH equations as pure pair kernels, and the drivers that loop over
// particles and their neighbours. Nothing here knows about grids, ranks or threads' origins.
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/neighbours.hpp"
#include "sphperf/sph/particles.hpp"

#include <cmath>
#include <vector>

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

// `back`: the pair's separation is taken that many seconds earlier along its relative velocity.
// With back = dt / 2 it is the rate at the middle of the step the velocities drift over, which
// makes the density update second order (at the end of the step, as before, it was first order:
// measured 2.0x error per halving of dt).
inline double continuity_term(const PairInput &in, const QuinticKernel &k, double back = 0) {
    const double dx = in.dx - back * in.dvx, dy = in.dy - back * in.dvy;
    const double r = std::sqrt(dx * dx + dy * dy);
    if (r == 0) // dW/dr / r -> const and the separation -> 0: no contribution
        return 0;
    const double f = k.derivative(r) / r;
    return in.m_j * f * (in.dvx * dx + in.dvy * dy);
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
// The same for particles [first, last) only.
void equation_of_state(Particles &p, const Physics &phys, std::size_t first, std::size_t last);

// Runs `term(sum, pair)` over the neighbours of every owned particle, then `finish(i, sum)`.
template <class Sum, Neighbourhood N, class Term, class Finish>
void for_each_neighbourhood(const Particles &p, const N &nb, Term &&term, Finish &&finish) {
    const std::size_t owned = nb.particles();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < owned; ++i) {
        Sum sum{};
        nb.for_each_neighbour(i, [&](std::uint32_t j) {
            const double dx = p.x[i] - p.x[j], dy = p.y[i] - p.y[j];
            const double r = std::sqrt(dx * dx + dy * dy);
            if (r == 0) // a fluid particle on a mirror line and its own image: no direction
                return;
            term(sum, PairInput{dx, dy, r, p.vx[i] - p.vx[j], p.vy[i] - p.vy[j], p.rho[i], p.rho[j],
                                p.p[i], p.p[j], p.mass[j]});
        });
        finish(i, sum);
    }
}

// Density rates of the owned particles (fluid and fixed wall particles), at separations taken
// `back` seconds earlier (see continuity_term).
template <Neighbourhood N>
void continuity(Particles &p, const N &nb, const Physics &phys, double back = 0) {
    const QuinticKernel k = phys.kernel();
    for_each_neighbourhood<double>(
        p, nb, [&](double &sum, const PairInput &in) { sum += continuity_term(in, k, back); },
        [&](std::size_t i, double sum) { p.drho[i] = sum; });
}

// Accelerations of the owned fluid particles (wall particles do not move).
template <Neighbourhood N> void momentum(Particles &p, const N &nb, const Physics &phys) {
    const QuinticKernel k = phys.kernel();
    for_each_neighbourhood<Acceleration>(
        p, nb,
        [&](Acceleration &sum, const PairInput &in) {
            const Acceleration a = momentum_term(in, k, phys.c0, phys.alpha);
            sum.ax += a.ax;
            sum.ay += a.ay;
        },
        [&](std::size_t i, const Acceleration &sum) {
            const bool fluid = p.kind[i] == Kind::fluid;
            p.ax[i] = fluid ? sum.ax : 0.0;
            p.ay[i] = fluid ? sum.ay - phys.gravity : 0.0;
        });
}

// Shepard filter: rho_i = sum_j m_j W_ij / sum_j (m_j / rho_j) W_ij over i and its neighbours;
// fluid densities only (wall densities follow the continuity equation).
template <Neighbourhood N> void shepard_filter(Particles &p, const N &nb, const Physics &phys) {
    const QuinticKernel k = phys.kernel();
    const std::size_t owned = nb.particles();
    std::vector<double> filtered(owned);
    const double w0 = k.value(0.0);
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < owned; ++i) {
        double num = p.mass[i] * w0, den = p.mass[i] / p.rho[i] * w0;
        nb.for_each_neighbour(i, [&](std::uint32_t j) {
            const double dx = p.x[i] - p.x[j], dy = p.y[i] - p.y[j];
            const double w = k.value(std::sqrt(dx * dx + dy * dy));
            num += p.mass[j] * w;
            den += p.mass[j] / p.rho[j] * w;
        });
        filtered[i] = num / den;
    }
    for (std::size_t i = 0; i < owned; ++i)
        if (p.kind[i] == Kind::fluid)
            p.rho[i] = filtered[i];
}

} // namespace sphperf::sph
