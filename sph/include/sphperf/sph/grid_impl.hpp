#pragma once
// Template part of grid.hpp: the neighbour search shared by the stored-list grid schemes.
#include "sphperf/timer.hpp"

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
    // concatenated in order: deterministic and free of atomics. Blocks are explicit so that
    // both passes below give a thread the same particles.
    auto &parts = nl.blocks;
    parts.resize(static_cast<std::size_t>(threads));
    const auto block = [&](int t) { return owned * static_cast<std::size_t>(t) / threads; };
    // Pass 1, the grid's work: candidates of the 3x3 cells within the radius, in cell order.
#pragma omp parallel num_threads(threads)
    {
        const int t = omp_get_thread_num();
        auto &mine = parts[static_cast<std::size_t>(t)];
        mine.clear();
        for (std::size_t i = block(t); i < block(t + 1); ++i) {
            const std::size_t before = mine.size();
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
                            mine.push_back(j);
                    });
            nl.offsets[i + 1] = static_cast<std::uint32_t>(mine.size() - before);
        }
    }
    const double sort_start = wall_seconds();
    // Pass 2, the price of sums in id order: each list sorted by id ((id, index) side by side,
    // so the sort compares contiguous keys), and the pairs counted.
    std::uint64_t pairs = 0, descents = 0;
    nl.descents_of.resize(owned);
#pragma omp parallel num_threads(threads) reduction(+ : pairs, descents)
    {
        const int t = omp_get_thread_num();
        auto &mine = parts[static_cast<std::size_t>(t)];
        thread_local std::vector<std::pair<std::int64_t, std::uint32_t>> local;
        std::size_t at = 0;
        for (std::size_t i = block(t); i < block(t + 1); ++i) {
            const std::size_t n = nl.offsets[i + 1];
            local.clear();
            for (std::size_t k = at; k < at + n; ++k)
                local.emplace_back(p.id[mine[k]], mine[k]);
            std::uint32_t down = 0;
            for (std::size_t k = 1; k < n; ++k)
                down += local[k].first < local[k - 1].first ? 1 : 0;
            descents += down;
            nl.descents_of[i] = down;
            std::sort(local.begin(), local.end());
            const std::int64_t id_i = p.id[i];
            for (std::size_t k = 0; k < n; ++k) {
                const auto [id_j, j] = local[k];
                if (j >= owned || id_j > id_i)
                    ++pairs; // owned-owned pairs once, pairs with transient particles here
                mine[at + k] = j;
            }
            at += n;
        }
    }
    const double sort_s = wall_seconds() - sort_start;
    for (std::size_t i = 0; i < owned; ++i)
        nl.offsets[i + 1] += nl.offsets[i];
    nl.index.clear();
    nl.index.reserve(nl.offsets[owned]);
    for (const auto &part : parts)
        nl.index.insert(nl.index.end(), part.begin(), part.end());
    return {pairs, nl.index.size(), descents, sort_s};
}

} // namespace sphperf::sph
