#include "sphperf/sph/physics.hpp"

namespace sphperf::sph {

void equation_of_state(Particles &p, const Physics &phys) {
    equation_of_state(p, phys, 0, p.size());
}

void equation_of_state(Particles &p, const Physics &phys, std::size_t first, std::size_t last) {
#pragma omp parallel for schedule(static)
    for (std::size_t i = first; i < last; ++i)
        p.p[i] = phys.pressure(p.rho[i]);
}

} // namespace sphperf::sph
