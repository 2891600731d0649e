#pragma once
// Cell grids of cell size 3h over one rank's slab (plus one ghost column each side and one
// ghost row below the floor). Two interchangeable schemes satisfy the CellGrid concept:
//   CellList  (thesis 3.3): linked lists rebuilt every step from the flat particle arrays;
//   CellTable (thesis 3.4): persistent per-cell hash tables keyed by particle id, where only
//                           particles that changed cell move between tables.
// The neighbour search is written once, for any CellGrid, with no virtual call.
#include "sphperf/sph/neighbours.hpp"
#include "sphperf/sph/particles.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <string_view>
#include <vector>

namespace sphperf::sph {

// The cells one rank stores: global columns [col_begin, col_end), rows [row_begin, row_end).
// Positions outside are filed in the nearest edge cell: correct, because pairs are always
// checked by distance, and cheap, because only a few splashes or wall layers fall there.
struct CellWindow {
    double cell_size = 1;
    int col_begin = 0, col_end = 1;
    int row_begin = -1, row_end = 1;

    int cols() const { return col_end - col_begin; }
    int rows() const { return row_end - row_begin; }
    int cells() const { return cols() * rows(); }
    int column_of(double x) const {
        return std::clamp(static_cast<int>(std::floor(x / cell_size)), col_begin, col_end - 1);
    }
    int row_of(double y) const {
        return std::clamp(static_cast<int>(std::floor(y / cell_size)), row_begin, row_end - 1);
    }
    int cell(int col, int row) const { return (row - row_begin) * cols() + (col - col_begin); }
    int cell_of(double x, double y) const { return cell(column_of(x), row_of(y)); }
};

// The cells a rank stores for its slab [first_column, end_column): one ghost column each side,
// rows from one below the floor up to the ceiling row. Domain::window's, and sph-scan-bench's
// when it rebuilds a checkpointed rank.
inline CellWindow slab_window(double cell_size, int first_column, int end_column, int cell_rows) {
    return {cell_size, first_column - 1, end_column + 1, -1, cell_rows};
}

template <class G>
concept CellGrid = requires(G g, const G cg, const Particles &p, const CellWindow &w,
                            std::int64_t id, void (*visit)(std::uint32_t)) {
    { G::name } -> std::convertible_to<std::string_view>;
    typename G::Neighbours;   // what the physics walks: a stored list, or the grid itself
    g.update(p, w);           // file every current particle in its cell
    g.remove_transient(p, w); // before ghosts and mirrors are dropped
    g.forget(id);             // an owned particle left this rank
    cg.for_each_in_cell(0, p, visit);
    { cg.last_moves() } -> std::convertible_to<std::size_t>;
    // What a checkpoint keeps of the grid: a restart at the same rank count resumes it as it
    // was (its order decides the counters, not the physics). Empty for a grid rebuilt each step.
    { cg.save_state() } -> std::same_as<std::vector<std::int64_t>>;
    g.restore_state(std::vector<std::int64_t>{});
};

// A grid that can also put the owned particles themselves in its order (Particles::permute),
// called after migration, when no transient particle exists (--reorder-every).
template <class G>
concept ReorderingGrid = requires(G g, Particles &p, const CellWindow &w) {
    g.reorder(p, w);
};

// Cell+List: head[cell] and next[particle], rebuilt every step; lock-free parallel insertion.
class CellList {
public:
    using Neighbours = NeighbourList;
    static constexpr std::string_view name = "list";

    void update(const Particles &p, const CellWindow &w);
    void remove_transient(const Particles &, const CellWindow &) {}
    void forget(std::int64_t) {}
    std::size_t last_moves() const { return moves_; }
    std::vector<std::int64_t> save_state() const { return {}; } // rebuilt every step
    void restore_state(const std::vector<std::int64_t> &) {}

    template <class F> void for_each_in_cell(int cell, const Particles &, F &&f) const {
        for (std::int32_t i = head_[static_cast<std::size_t>(cell)]; i >= 0;
             i = next_[static_cast<std::size_t>(i)])
            f(static_cast<std::uint32_t>(i));
    }

private:
    std::vector<std::int32_t> head_, next_;
    std::size_t moves_ = 0;
};

// Cell+Table: persistent cells; a particle moves between cells only when it changes cell.
// Each cell keeps its members densely as (id, index), so a scan reads contiguous memory. The
// table keyed by particle id is direct-address: ids are dense (setup assigns them), so
// id -> (cell, slot) is an array lookup, a perfect hash, and insert and remove are O(1).
class CellTable {
public:
    using Neighbours = NeighbourList;
    static constexpr std::string_view name = "table";

    void update(const Particles &p, const CellWindow &w);
    void remove_transient(const Particles &p, const CellWindow &w);
    void forget(std::int64_t id);
    std::size_t last_moves() const { return moves_; }
    // The window's cell count, then per cell its member count and (id, index) pairs in order.
    std::vector<std::int64_t> save_state() const;
    void restore_state(const std::vector<std::int64_t> &s);

    template <class F> void for_each_in_cell(int cell, const Particles &, F &&f) const {
        for (const Member &m : cells_[static_cast<std::size_t>(cell)])
            f(m.index);
    }
    std::size_t members(int cell) const { return cells_[static_cast<std::size_t>(cell)].size(); }

private:
    struct Member {
        std::int64_t id;
        std::uint32_t index; // position in the particle arrays, refreshed every update
    };
    void ensure_ids(std::int64_t id);
    void insert(std::int64_t id, std::uint32_t index, std::int32_t cell);
    std::vector<std::vector<Member>> cells_;
    std::vector<std::int32_t> home_;     // id -> cell it is filed in, -1 if none
    std::vector<std::uint32_t> slot_;    // id -> position in its cell
    std::vector<std::int32_t> new_cell_; // scratch, per particle
    std::size_t moves_ = 0;
    int window_cells_ = -1;
};

// Two particles interact unless neither is fluid (walls and mirrors do not act on each other).
inline bool interacting(Kind a, Kind b) {
    return a == Kind::fluid || b == Kind::fluid;
}

// Neighbour lists of the owned particles: every particle within `radius` (strictly) in the 3x3
// cells around, sorted by id. Works on any CellGrid.
template <CellGrid G>
PairCounts find_neighbours(const G &grid, const Particles &p, const CellWindow &w, double radius,
                           NeighbourList &nl);

// Stored-list schemes: the search fills the list and keeps its counts.
template <CellGrid G>
void build_neighbours(const G &grid, const Particles &p, const CellWindow &w, double radius,
                      NeighbourList &nl) {
    nl.counts = find_neighbours(grid, p, w, radius, nl);
}

} // namespace sphperf::sph

#include "sphperf/sph/grid_impl.hpp"
