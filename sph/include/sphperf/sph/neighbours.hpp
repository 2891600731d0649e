#pragma once
// The neighbour list every grid scheme produces: for each owned particle i, the indices of the
// particles within 3h that interact with it, sorted by particle id so that sums run in the same
// order whatever grid, thread count or rank layout found them (trajectories then agree to the
// last bit across grids).
#include <cstdint>
#include <vector>

namespace sphperf::sph {

struct NeighbourList {
    std::vector<std::uint32_t> offsets; // size owned + 1
    std::vector<std::uint32_t> index;   // neighbour indices, offsets[i] .. offsets[i + 1]

    std::size_t particles() const { return offsets.empty() ? 0 : offsets.size() - 1; }
    std::size_t interactions() const { return index.size(); }
};

} // namespace sphperf::sph
