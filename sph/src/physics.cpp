#include "sphperf/sph/physics.hpp"

namespace sphperf::sph {

void equation_of_state(Particles &p, const Physics &phys) {
    const std::size_t n = p.size();
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i)
        p.p[i] = phys.pressure(p.rho[i]);
}

} // namespace sphperf::sph
