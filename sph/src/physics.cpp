#include "sphperf/sph/physics.hpp"

namespace sphperf::sph {

void equation_of_state(Particles &p, const Physics &phys) {
    const std::size_t n = p.size();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i)
        p.p[i] = phys.pressure(p.rho[i]);
}

namespace {
// Runs `term(i, pair)` over the neighbours of every owned particle; `finish(i, sums)` stores.
template <class Sum, class Term, class Finish>
void for_each_neighbourhood(const Particles &p, const NeighbourList &nl, Term &&term,
                            Finish &&finish) {
    const std::size_t owned = nl.particles();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < owned; ++i) {
        Sum sum{};
        for (std::uint32_t e = nl.offsets[i]; e < nl.offsets[i + 1]; ++e) {
            const std::uint32_t j = nl.index[e];
            const double dx = p.x[i] - p.x[j], dy = p.y[i] - p.y[j];
            const double r = std::sqrt(dx * dx + dy * dy);
            if (r == 0) // a fluid particle on a mirror line and its own image: no direction
                continue;
            term(sum, PairInput{dx, dy, r, p.vx[i] - p.vx[j], p.vy[i] - p.vy[j], p.rho[i], p.rho[j],
                                p.p[i], p.p[j], p.mass[j]});
        }
        finish(i, sum);
    }
}
} // namespace

void continuity(Particles &p, const NeighbourList &nl, const Physics &phys) {
    const QuinticKernel k = phys.kernel();
    for_each_neighbourhood<double>(
        p, nl, [&](double &sum, const PairInput &in) { sum += continuity_term(in, k); },
        [&](std::size_t i, double sum) { p.drho[i] = sum; });
}

void momentum(Particles &p, const NeighbourList &nl, const Physics &phys) {
    const QuinticKernel k = phys.kernel();
    for_each_neighbourhood<Acceleration>(
        p, nl,
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

void shepard_filter(Particles &p, const NeighbourList &nl, const Physics &phys) {
    const QuinticKernel k = phys.kernel();
    const std::size_t owned = nl.particles();
    std::vector<double> filtered(owned);
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < owned; ++i) {
        const double w0 = k.value(0.0);
        double num = p.mass[i] * w0, den = p.mass[i] / p.rho[i] * w0;
        for (std::uint32_t e = nl.offsets[i]; e < nl.offsets[i + 1]; ++e) {
            const std::uint32_t j = nl.index[e];
            const double dx = p.x[i] - p.x[j], dy = p.y[i] - p.y[j];
            const double w = k.value(std::sqrt(dx * dx + dy * dy));
            num += p.mass[j] * w;
            den += p.mass[j] / p.rho[j] * w;
        }
        filtered[i] = num / den;
    }
    for (std::size_t i = 0; i < owned; ++i)
        if (p.kind[i] == Kind::fluid) // wall densities follow the continuity equation only
            p.rho[i] = filtered[i];
}

} // namespace sphperf::sph
