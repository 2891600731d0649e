#pragma once
// The neighbour list every grid scheme produces: for each owned particle i, the indices of the
// particles within 3h that interact with it, sorted by particle id so that sums run in the same
// order whatever grid, thread count or rank layout found them (trajectories then agree to the
// last bit across grids).
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace sphperf::sph {

struct PairCounts {
    std::uint64_t pairs = 0;        // unordered pairs within 3h with at least one fluid particle
    std::uint64_t interactions = 0; // ordered pairs (i, j) contributing to an owned particle i
    std::uint64_t descents = 0;     // stored lists: neighbours found after one of larger id
    double sort_s = 0;              // stored lists: time spent ordering them by id
};

struct NeighbourList {
    std::vector<std::uint32_t> offsets; // size owned + 1
    std::vector<std::uint32_t> index;   // neighbour indices, offsets[i] .. offsets[i + 1]
    PairCounts counts;                  // of the last search
    // Search scratch kept across steps (one block per thread): no allocation or page fault in
    // the search once the lists have reached their size.
    std::vector<std::vector<std::uint32_t>> blocks;
    // Stored lists: each owned particle's descents, neighbours found right after one of larger
    // id (before the id sort). The disorder sits where the water moves, so the report adds
    // them up per cell column and the model gives each rank its own columns' memory order.
    std::vector<std::uint32_t> descents_of;

    std::size_t particles() const { return offsets.empty() ? 0 : offsets.size() - 1; }
    std::size_t interactions() const { return index.size(); }
    std::size_t interactions_of(std::size_t i) const { return offsets[i + 1] - offsets[i]; }

    template <class F> void for_each_neighbour(std::size_t i, F &&f) const {
        for (std::uint32_t e = offsets[i]; e < offsets[i + 1]; ++e)
            f(index[e]);
    }
};

// What the physics needs from a neighbour search: how many owned particles, and their
// neighbours one particle at a time. A stored list satisfies it; so can a scheme that walks
// sorted cells on the fly and stores no pairs.
template <class N>
concept Neighbourhood = requires(const N &n, std::size_t i, void (*f)(std::uint32_t)) {
    { n.particles() } -> std::convertible_to<std::size_t>;
    n.for_each_neighbour(i, f);
};

} // namespace sphperf::sph
