#pragma once
// Where the slabs are cut: column indices cuts[0] = 0 < cuts[1] < ... < cuts[ranks] = columns,
// rank r owning columns [cuts[r], cuts[r + 1]). Equal cuts are the thesis' (3.1); balanced cuts
// give every rank as equal a predicted cost as whole columns allow. Pure functions: the app and
// the performance model cut with the same code.
#include <algorithm>
#include <cmath>
#include <numeric>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace sphperf::sph {

// The thesis' slabs: rank r starts at floor(r columns / ranks).
inline std::vector<int> equal_cuts(int ranks, int columns) {
    std::vector<int> cuts(static_cast<std::size_t>(ranks) + 1);
    for (int r = 0; r <= ranks; ++r)
        cuts[static_cast<std::size_t>(r)] =
            static_cast<int>(static_cast<long long>(r) * columns / ranks);
    return cuts;
}

// Throws std::invalid_argument naming the first violation: cuts must start at 0, end at
// `columns`, and increase strictly (every rank at least one column).
inline void check_cuts(std::span<const int> cuts, int ranks, int columns) {
    auto fail = [&](const std::string &why) {
        std::string list;
        for (int c : cuts) {
            if (!list.empty())
                list += ',';
            list += std::to_string(c);
        }
        throw std::invalid_argument("slab cuts [" + list + "] for " + std::to_string(ranks) +
                                    " ranks over " + std::to_string(columns) + " columns: " + why);
    };
    if (cuts.size() != static_cast<std::size_t>(ranks) + 1)
        fail("expected " + std::to_string(ranks + 1) + " cut points");
    if (cuts.front() != 0 || cuts.back() != columns)
        fail("expected the first at 0 and the last at the column count");
    for (std::size_t r = 0; r + 1 < cuts.size(); ++r)
        if (cuts[r + 1] <= cuts[r])
            fail("rank " + std::to_string(r) + " would own no column");
}

// Cuts that minimise the largest slab cost (sum of `cost` over its columns), every rank keeping
// at least one column. The smallest feasible bottleneck is found by bisection on a greedy fill
// (exact to 1e-12 of the total); among the cuts that achieve it, each cut is then placed
// nearest its share of the prefix sum, so that spare capacity is spread rather than left to the
// last ranks. Throws std::invalid_argument for more ranks than columns or a cost that is
// negative or not finite.
inline std::vector<int> balanced_cuts(std::span<const double> cost, int ranks) {
    const int columns = static_cast<int>(cost.size());
    if (ranks < 1 || ranks > columns)
        throw std::invalid_argument(std::to_string(ranks) + " ranks over " +
                                    std::to_string(columns) +
                                    " columns: each rank needs at least one column");
    for (double c : cost)
        if (!std::isfinite(c) || c < 0)
            throw std::invalid_argument("column cost " + std::to_string(c) +
                                        ": expected a finite number >= 0");
    std::vector<double> prefix(static_cast<std::size_t>(columns) + 1, 0.0);
    for (int c = 0; c < columns; ++c)
        prefix[static_cast<std::size_t>(c) + 1] =
            prefix[static_cast<std::size_t>(c)] + cost[static_cast<std::size_t>(c)];
    const double total = prefix.back();
    auto load = [&](int a, int b) {
        return prefix[static_cast<std::size_t>(b)] - prefix[static_cast<std::size_t>(a)];
    };
    // Greedy fill under bottleneck b: every rank takes as many columns as fit, leaving one
    // column for each rank after it. Returns the cuts, or nothing if the last rank overflows.
    auto fill = [&](double b, std::vector<int> &cuts) {
        cuts.assign(static_cast<std::size_t>(ranks) + 1, 0);
        int c = 0;
        for (int r = 0; r < ranks; ++r) {
            int end = c + 1; // at least one column
            const int last = columns - (ranks - r - 1);
            if (r + 1 == ranks)
                end = columns;
            else
                while (end < last && load(c, end + 1) <= b)
                    ++end;
            if (load(c, end) > b)
                return false;
            c = end;
            cuts[static_cast<std::size_t>(r) + 1] = end;
        }
        return true;
    };
    std::vector<int> cuts;
    double lo = 0, hi = total;
    for (int c = 0; c < columns; ++c)
        lo = std::max(lo, cost[static_cast<std::size_t>(c)]);
    lo = std::max(lo, total / ranks);
    if (!fill(lo, cuts)) {
        for (int it = 0; it < 200 && hi - lo > 1e-12 * std::max(total, 1e-300); ++it) {
            const double mid = 0.5 * (lo + hi);
            (fill(mid, cuts) ? hi : lo) = mid;
        }
        fill(hi, cuts);
    }
    double worst = 0;
    for (int r = 0; r < ranks; ++r)
        worst = std::max(
            worst, load(cuts[static_cast<std::size_t>(r)], cuts[static_cast<std::size_t>(r) + 1]));
    // Spread the slack: move each cut toward r * total / ranks while no slab exceeds `worst`,
    // sweeping until no cut moves (each move strictly shrinks a cut's distance to its share).
    for (bool moved = true; moved;) {
        moved = false;
        for (int r = 1; r < ranks; ++r) {
            const double target = total * r / ranks;
            auto &cut = cuts[static_cast<std::size_t>(r)];
            const int lo_c = cuts[static_cast<std::size_t>(r) - 1] + 1;
            const int hi_c = cuts[static_cast<std::size_t>(r) + 1] - 1;
            auto ok = [&](int c) {
                return c >= lo_c && c <= hi_c &&
                       load(cuts[static_cast<std::size_t>(r) - 1], c) <= worst &&
                       load(c, cuts[static_cast<std::size_t>(r) + 1]) <= worst;
            };
            auto gap = [&](int c) {
                return std::abs(prefix[static_cast<std::size_t>(c)] - target);
            };
            const int was = cut;
            while (ok(cut - 1) && gap(cut - 1) < gap(cut))
                --cut;
            while (ok(cut + 1) && gap(cut + 1) < gap(cut))
                ++cut;
            moved = moved || cut != was;
        }
    }
    return cuts;
}

// Largest slab cost under the given cuts.
inline double max_slab_cost(std::span<const double> cost, std::span<const int> cuts) {
    double worst = 0;
    for (std::size_t r = 0; r + 1 < cuts.size(); ++r)
        worst = std::max(worst,
                         std::accumulate(cost.begin() + cuts[r], cost.begin() + cuts[r + 1], 0.0));
    return worst;
}

} // namespace sphperf::sph
