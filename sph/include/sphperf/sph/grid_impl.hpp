#pragma once
// Template part of grid.hpp: the neighbour search shared by all grid schemes.
#include <omp.h>

namespace sphperf::sph {

template <CellGrid G>
PairCounts find_neighbours(const G &grid, const Particles &p, const CellWindow &w, double radius,
                           NeighbourList &nl) {
    const std::size_t owned = p.owned();
    const double r2max = radius * radius;
    nl.offsets.assign(owned + 1, 0);
    const int threads = omp_get_max_threads();
    // Each thread fills its own list for a contiguous block of particles, then the blocks are
    // concatenated in order: deterministic and free of atomics.
    auto &parts = nl.blocks;
    parts.resize(static_cast<std::size_t>(threads));
    std::uint64_t pairs = 0, descents = 0;
#pragma omp parallel num_threads(threads) reduction(+ : pairs, descents)
    {
        auto &mine = parts[static_cast<std::size_t>(omp_get_thread_num())];
        mine.clear();
        // (id, index) side by side: the sort compares contiguous keys, no gather through p.id.
        thread_local std::vector<std::pair<std::int64_t, std::uint32_t>> local;
#pragma omp for schedule(static)
        for (std::size_t i = 0; i < owned; ++i) {
            local.clear();
            const int ci = w.column_of(p.x[i]), ri = w.row_of(p.y[i]);
            const double xi = p.x[i], yi = p.y[i];
            const bool fluid_i = p.kind[i] == Kind::fluid;
            for (int c = std::max(ci - 1, w.col_begin); c <= std::min(ci + 1, w.col_end - 1); ++c)
                for (int r = std::max(ri - 1, w.row_begin); r <= std::min(ri + 1, w.row_end - 1);
                     ++r)
                    grid.for_each_in_cell(w.cell(c, r), p, [&](std::uint32_t j) {
                        if (j == i || (!fluid_i && p.kind[j] != Kind::fluid))
                            return;
                        const double dx = xi - p.x[j], dy = yi - p.y[j];
                        if (dx * dx + dy * dy < r2max)
                            local.emplace_back(p.id[j], j);
                    });
            for (std::size_t k = 1; k < local.size(); ++k)
                descents += local[k].first < local[k - 1].first ? 1 : 0;
            std::sort(local.begin(), local.end());
            const std::int64_t id_i = p.id[i];
            for (const auto &[id_j, j] : local)
                if (j >= owned || id_j > id_i)
                    ++pairs; // owned-owned pairs once, pairs with transient particles here
            nl.offsets[i + 1] = static_cast<std::uint32_t>(local.size());
            for (const auto &e : local)
                mine.push_back(e.second);
        }
    }
    for (std::size_t i = 0; i < owned; ++i)
        nl.offsets[i + 1] += nl.offsets[i];
    nl.index.clear();
    nl.index.reserve(nl.offsets[owned]);
    for (const auto &part : parts)
        nl.index.insert(nl.index.end(), part.begin(), part.end());
    return {pairs, nl.index.size(), descents};
}

} // namespace sphperf::sph
