#pragma once
// Initial particles and boundary particles. Ids are global and dense: fluid 0..Nf-1, fixed wall
// particles next, and mirror images Nf + Nb + 3 * source + k (k: wall, floor, corner image).
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/particles.hpp"

#include <cstdint>
#include <vector>

namespace sphperf::sph {

// Fluid block on a lattice of spacing delta, hydrostatic density (pressure rho0 g depth).
std::vector<ParticleRecord> make_fluid(const Geometry &geo, const Physics &phys);

// Fixed boundary (Dirichlet): layers of wall particles under the floor and outside both walls,
// deep enough to fill the kernel support (ceil(3h / delta) layers), up to the ceiling.
std::vector<ParticleRecord> make_walls(const Geometry &geo, const Physics &phys,
                                       std::int64_t first_id);

// Layers of wall particles: enough to cover the whole kernel support.
int wall_layers(const Physics &phys);

// Mirror boundary (Neumann): appends the images, across the walls and the floor, of owned
// fluid particles closer than 3h to them, with the normal velocity reversed (free slip).
// `sources` receives, per appended mirror, the index of the fluid particle it images.
// Returns the number appended.
std::size_t add_mirrors(Particles &p, const Geometry &geo, const Physics &phys,
                        std::int64_t first_mirror_id, std::vector<std::uint32_t> &sources);

// Mirror boundary: a fluid particle that crossed a wall or the floor during the drift is
// reflected back (position and normal velocity), the free-slip condition applied to the
// particle itself. Returns how many were reflected (reported, never silent).
std::size_t reflect_at_walls(Particles &p, const Geometry &geo);

// After the sources' density changed: mirrors appended from index `first` take it again.
void refresh_mirrors(Particles &p, std::size_t first, const std::vector<std::uint32_t> &sources);

} // namespace sphperf::sph
