#pragma once
// Cell+Sorted, the third grid scheme: every step the particles are copied in cell order
// (counting sort), by id within a cell. Its cells are the window's columns cut into
// `rows_per_cell` rows per window cell, numbered column by column: the rows within 3h of a
// particle in a neighbouring column are one contiguous range, so a particle's neighbourhood is
// three ranges, each (2 rows_per_cell + 1) / rows_per_cell cells tall instead of 3. No pair is
// stored: density, forces and the Shepard filter walk the ranges directly, each particle's sum by
// one thread in a fixed order (columns west to east, rows bottom to top, ids within a cell, and a
// fixed 16-lane split of the in-range candidates so ordered, or an 8-lane one of each range for
// Shepard). The result therefore does not depend on the thread count, the rank count, or where
// the arrays sit in memory.
#include "sphperf/kernel_isa.hpp"
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/grid.hpp"
#include "sphperf/sph/kernel.hpp"
#include "sphperf/sph/particles.hpp"

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <array>
#include <atomic>
#include <concepts>
#include <cstdint>
#include <functional>
#include <memory>
#include <new>
#include <span>
#include <string_view>
#include <utility>
#include <vector>

namespace sphperf::sph {

struct SortedNeighbours;

#if defined(__AVX2__)
// Four doubles and eight floats as GCC vectors (arithmetic, comparisons and ?: work on them):
// __m256d and __m256 without their may_alias. The AVX2 pair loops compute on Lanes8.
using Lanes4 = double __attribute__((vector_size(32)));
using Lanes8 = float __attribute__((vector_size(32)));
#endif

// The precision of the pair terms: the packed separations, the records, the kernel, the
// velocity and pressure terms and their per-lane sums. Single: the AVX2 loops then take eight
// pairs per instruction instead of four, and the dam break's compute fell to about 0.82 of the
// double loops' on the Zen 3 host (sph/NOTES.md, session 67). Positions, the neighbour
// decision (distance^2 < (3h)^2), the particles' fields and the integration stay double; the
// physics tests hold (they and the tolerances this changed: sph/NOTES.md, session 67).
using PairReal = float;

// The window columns a physics pass covers: [first, last], or with `outside` every other one
// (--overlap computes the columns that need no ghost while the ghosts travel, then the rest).
struct ColumnSet {
    int first = 0, last = 1 << 30;
    bool outside = false;
    bool contains(int col) const { return (col >= first && col <= last) != outside; }
    ColumnSet complement() const { return {first, last, !outside}; }
};

// Cache-line aligned storage for the packed candidates and the pair records: the pair loops
// read them in whole vectors, and from a 16-byte aligned heap block every such load splits two
// cache lines (measured: the packing's 9 % gain gone when mpirun's environment shifted the heap).
template <class T> struct CacheLineAllocator {
    using value_type = T;
    CacheLineAllocator() = default;
    template <class U> CacheLineAllocator(const CacheLineAllocator<U> &) {}
    T *allocate(std::size_t n) {
        return static_cast<T *>(::operator new (n * sizeof(T), std::align_val_t{64}));
    }
    void deallocate(T *p, std::size_t) { ::operator delete (p, std::align_val_t{64}); }
    friend bool operator==(const CacheLineAllocator &, const CacheLineAllocator &) { return true; }
};

// Where the build has AVX2 but not AVX-512 the pair loops are written for 8-lane vectors of
// floats (sorted.cpp, the same pair terms as the compiler's 16-lane loops) and read a
// neighbour's vx, vy, rho and P / rho^2 as one 16-byte record, `View::records`, eight of them
// transposed into four vectors: GCC emulates a gather with a scalar load and a shuffle a lane,
// and the force pass gathers five fields a pair. On the Zen 3 host of session 63 (dam break,
// scale 1; then doubles, four a vector) this took 13 % off the compute at 1 thread and 12 % at
// 2 (sph/NOTES.md, session 63). AVX-512 kernels (kernel_isa.hpp) keep the compiler's loops,
// measured faster on the Intel host; on the AMD Zen 4 host the AVX2 kernels are built instead.
#if defined(SPHPERF_AVX2_KERNELS)
inline constexpr bool pair_records = true;
#else
inline constexpr bool pair_records = false;
#endif

class CellSorted {
public:
    static constexpr std::string_view name = "sorted";
    using Neighbours = SortedNeighbours;
    // Rows of the sorted grid per window cell: candidates examined per particle fall from
    // 3 x 3 cells to 3 x (2 rows_per_cell + 1) / rows_per_cell, while each range stays long
    // enough to fill vectors (500 dam-break steps, 1 thread: 1, 2, 3, 4 and 6 rows took
    // about 4.5, 4.0, 3.8, 3.6 and 3.7 s).
    static constexpr int rows_per_cell = 4;

    // The sorted copy: what the inner loops read, contiguous per cell.
    struct View {
        // vx, vy and P / rho^2 without pair_records only (with them the records hold these,
        // and a particle's own come from Particles); rho after refresh_filter_fields (and
        // refresh_density without pair_records); mass where the masses differ (common_mass 0),
        // else after refresh_filter_fields.
        const double *x, *y, *vx, *vy, *rho, *p_over_rho2, *mass;
        const double *fluid, *remote; // 1 or 0: a fluid particle; not owned by this rank
        // With pair_records: per sorted position vx, vy, rho, P / rho^2 (PairReal), 16-byte
        // aligned
        // (rho and P / rho^2 as refresh_density left them); else null.
        const PairReal *records;
        const std::uint32_t *orig;  // sorted position -> index in Particles
        const std::uint32_t *start; // cell -> first sorted position; start[cells] = size
        int cols, rows;
        std::size_t owned;                  // a sorted particle is owned when orig < owned
        const std::uint32_t *blocks;        // thread t's cells: [blocks[t], blocks[t + 1])
        int threads;                        // the team size the blocks were cut for
        const std::uint64_t *cost;          // candidates examined in cells [0, c)
        const std::uint8_t *remote_columns; // 1 where a column holds particles not owned
        // Per column, rows + 1 entries: the fluid particles in its rows [0, r). A wall
        // particle's density pass skips the ranges without fluid (a dry wall: all of them).
        const std::uint32_t *fluid_below;
        std::uint32_t fluid_in(int col, int row_begin, int row_end) const {
            const std::uint32_t *f = fluid_below + static_cast<std::size_t>(col) * (rows + 1);
            return f[row_end] - f[row_begin];
        }
        // The mass of every particle when they all have one (every setup here), else 0: the
        // pair loops then take it as a constant instead of gathering it per neighbour.
        double common_mass;
    };

    void update(const Particles &p, const CellWindow &w) { update(p, w, 0, 0); } // sort, copy
    // Puts the owned particles themselves in cell order (fluid, then walls, each by cell; no
    // transient particle may exist): update's copy and the passes' writes back then walk
    // Particles in order. Changes no result (every sum runs in cell and id order, wherever a
    // particle sits); it did not pay on the dam break (sph/NOTES.md), so it is optional.
    void reorder(Particles &p, const CellWindow &w);
    // --overlap: sorts the particles present now and keeps `west` and `east` positions free at
    // the two ends for the ghosts in flight, which can only land in the window's edge columns
    // (so those hold nothing else); add_ghosts files them, p[first, p.size()), once they are
    // here. The result is the layout update() gives with the ghosts present.
    void update(const Particles &p, const CellWindow &w, std::size_t west, std::size_t east);
    void add_ghosts(const Particles &p, std::size_t first);
    // The columns whose particles and neighbours are all here while ghosts are pending.
    ColumnSet columns_without_ghosts() const {
        return {west_ > 0 ? 2 : 0, east_ > 0 ? cols_ - 3 : cols_ - 1, false};
    }
    void remove_transient(const Particles &, const CellWindow &) {}
    void forget(std::int64_t) {}
    std::size_t last_moves() const { return moves_; }
    std::vector<std::int64_t> save_state() const { return {}; } // sorted anew every step
    void restore_state(const std::vector<std::int64_t> &) {}
    // Window cell numbering (row-major, CellWindow::cell) in, original indices out.
    template <class F> void for_each_in_cell(int cell, const Particles &, F &&f) const {
        const int k = first_sorted_cell(cell); // the window cell's rows are contiguous
        for (std::uint32_t s = start_[static_cast<std::size_t>(k)];
             s < start_[static_cast<std::size_t>(k + rows_per_cell)]; ++s)
            f(orig_[s]);
    }
    // Copies density and P / rho^2, which the sort leaves out: they change between the sort and
    // the passes that read them (continuity, equation of state). With pair_records into the
    // records only: no pair loop reads the doubles, and a particle's own come from Particles.
    void refresh_density(const Particles &p);
    // The sorted densities as doubles and the masses, which update() copies only where they
    // differ (View::mass): for the pass that reads them (the Shepard filter, every few steps).
    void refresh_filter_fields(const Particles &p);
    // The same for the ghost positions only (their density came after the others'): the slots
    // kept for them (--overlap), else the columns holding any.
    void refresh_ghost_density(const Particles &p);
    View view() const;
    // The owned fluid particles by the threads' blocks of the last update: thread t's block
    // holds split[t + 1] - split[t] of them (team + 1 entries, split.back() = fluid). The
    // per-particle passes (kicks, drift, state check, the next update's sort) take index
    // ranges of these sizes: the setup numbers the fluid column by column, so index ranges then
    // hold about the particles of each thread's cells, and the lines a thread writes there are
    // the ones it reads in its block (sph/NOTES.md, session 86).
    std::span<const std::size_t> fluid_split() const { return fluid_split_; }
    // A thread's seconds in a pair pass and the cost (candidates examined) of the cells it
    // went through (inside the parallel region; each thread writes its own entry): the next
    // cut_blocks gives the threads shares of the cost by how fast they got through it.
    // Another team size than the blocks' is not booked.
    void add_pass_time(int thread, double seconds, std::uint64_t cost) {
        if (static_cast<std::size_t>(thread) < pass_time_.size() &&
            pass_time_.size() == static_cast<std::size_t>(threads_)) {
            pass_time_[static_cast<std::size_t>(thread)].seconds += seconds;
            pass_time_[static_cast<std::size_t>(thread)].cost += static_cast<double>(cost);
        }
    }
    // The pair passes' cells, handed out in chunks: each thread's block is cut into
    // `chunks_per_block` chunks of equal cost; a thread takes its own block's from the front,
    // then, once they are gone, the other threads' from their back ends. The cut by measured
    // speed is right on average, but the two vCPUs' speeds change within a step: the slower
    // thread took 6-8 % longer than the mean of the two over a dam break's passes
    // (sph/NOTES.md, session 62). start_pass() before each pass's parallel region; then
    // next_cells(thread, first, last) gives [first, last) and false when no chunk is left
    // (only with the team size the blocks were cut for).
    static constexpr int chunks_per_block = 32;
    void start_pass();
    bool next_cells(int thread, std::uint32_t &first, std::uint32_t &last);
    // sweep_forces' columns, handed out the same way: each block rounded to whole columns, cut
    // into `column_chunks_per_block` chunks, each 3/5 the cost of the one before (fewer columns
    // than cells: a chunk taken by another thread costs the sweep a fresh pack of its two edge
    // columns; the small ones at the back keep the threads' ends close).
    // start_sweep() before the sweep's parallel region; next_columns gives [first, last).
    static constexpr int column_chunks_per_block = 8;
    void start_sweep();
    bool next_columns(int thread, std::uint32_t &first, std::uint32_t &last);
    // For tests: every thread takes its own columns' chunks from the back too, as a thief
    // does, so each chunk starts a run of its own whatever the timing.
    bool sweep_from_back = false;

    // sweep_forces' scratch, kept across steps (sorted.cpp): per column, a flag set once its
    // density pass and density update are done; per sorted position, where the fluid
    // particle's packed neighbours lie in its thread's store; per thread, the packs of two
    // columns in turn and those of its first column (whose force pass comes last), and the
    // columns whose force pass waits for a neighbour column (packed afresh then).
    struct SweepStore {
        std::vector<std::uint32_t, CacheLineAllocator<std::uint32_t>> index;
        std::vector<PairReal, CacheLineAllocator<PairReal>> dx, dy;
        std::size_t used = 0;
    };
    struct SweepThread {
        std::array<SweepStore, 3> stores;
        std::vector<int> waiting, held; // for a neighbour's flag; for the ghosts' densities
    };
    struct Sweep {
        std::unique_ptr<std::atomic<int>[]> column_done;
        int columns = 0;
        std::vector<std::uint32_t> offset, length;
        std::vector<SweepThread> threads;
    };
    Sweep &sweep() { return sweep_; }
    // refresh_density for sorted positions [from, to) only.
    void refresh_density(const Particles &p, std::size_t from, std::size_t to);

private:
    int first_sorted_cell(int window_cell) const {
        return (window_cell % cols_) * rows_ + (window_cell / cols_) * rows_per_cell;
    }
    void set_window(const CellWindow &w);
    std::uint32_t key_of(double x, double y) const; // sorted cell of a position
    // Copies sorted positions [from, to) from p, then marks columns [first_column,
    // last_column) anew (remote_columns_, fluid_below_): the density pass counts remote
    // partners in the columns holding some only, and a wall particle looks at fluid only.
    // `remote_flags` false: every position is owned and remote_ already holds zeros (neither
    // written nor read).
    void copy_fields(const Particles &p, std::size_t from, std::size_t to, int first_column,
                     int last_column, bool count_fluid = false, bool remote_flags = true);
    // Stable counting sort of [first, last) by key_: starts[c] becomes the first position of
    // cell c (cells + 1 entries, counted from `base`), out[starts[c]...] its indices in order.
    // Called by every thread of a parallel region (prepare_sort before it, for its team size);
    // it ends without a barrier. Thread t takes the indices [first + split[t], first +
    // split[t + 1]) (team + 1 entries in order; empty: equal shares) and sums the offsets of
    // cells [cuts[t], cuts[t + 1]) (empty: equal shares). The histograms are 0 between calls,
    // the offsets are written only where a thread has particles, and each thread clears its own
    // entries after filing: with a split that follows the cuts (update: the fluid split and the
    // blocks), a thread's histogram lines stay on its core, where equal shares, a full zeroing
    // and a write to every entry had each core fetch half of the other's every step
    // (sph/NOTES.md, session 86).
    void prepare_sort(int threads, std::vector<std::uint32_t> &starts);
    void sort_by_key(std::size_t first, std::size_t last, std::size_t base,
                     std::vector<std::uint32_t> &starts, std::vector<std::uint32_t> &out,
                     std::span<const std::size_t> split = {},
                     std::span<const std::uint32_t> cuts = {});
    void sort_cells_by_id(const Particles &p, std::size_t first_cell, std::size_t last_cell);
    // Cuts the cells into one contiguous block per thread, of equal candidates examined (the
    // particles of a cell times the candidates in the ranges around it) weighted by the
    // threads' speeds, and each block into its chunks: every pass gives a thread the same
    // block, so it reads what it wrote and the threads share only the cells at the cut and
    // the few chunks taken at a pass's end. A dynamic schedule pays an inter-core round trip
    // per chunk and moves the data between cores every pass; this VM's inter-core latency
    // switches between about 80 and 350 ns (sph/NOTES.md).
    void cut_blocks();
    // Each thread's share of the cost for cut_blocks: equal, or by the threads' measured
    // seconds per unit of cost (add_pass_time) at this team size. The bits of every result do
    // not depend on the cut, only its speed does.
    std::vector<double> thread_shares(int threads);
    // Weight of the latest step in the smoothed seconds per unit of cost.
    static constexpr double speed_smoothing = 0.1;
    struct alignas(64) PassTime { // one cache line each: the threads write them concurrently
        double seconds = 0, cost = 0;
    };
    std::vector<PassTime> pass_time_; // this step's, per thread
    // Chunk c of thread t's block: cells [chunk_bounds_[k], chunk_bounds_[k + 1]), k = t x
    // chunks_per_block + c. A thread's queue packs its first chunk not taken (low 32 bits) and
    // its end (high 32 bits): the owner advances the first, a thief lowers the end.
    std::vector<std::uint32_t> chunk_bounds_;
    std::vector<std::uint32_t> column_bounds_; // the same for start_sweep, in columns
    // Takes a chunk of bounds (chunk_bounds_ or column_bounds_, as the queues were reset): the
    // thread's own from the front, or the others' from their back ends; false when none is left.
    bool take_chunk(const std::vector<std::uint32_t> &bounds, int thread, std::uint32_t &first,
                    std::uint32_t &last, bool own_from_back = false);
    void reset_queues(int per_block);
    struct alignas(64) ChunkQueue { // one cache line each: mostly its owner's
        std::atomic<std::uint64_t> range{0};
    };
    std::unique_ptr<ChunkQueue[]> queues_;
    int queue_count_ = 0;
    std::vector<double> seconds_per_cost_; // smoothed, per thread
    // This thread's sorted positions (inside a parallel region): those of its block's cells.
    std::pair<std::size_t, std::size_t> thread_positions() const;
    // The column whose first cell is nearest to `cell`: where a block of cells is cut into
    // whole columns (start_sweep's chunks, copy_fields' column marks).
    int column_nearest(std::size_t cell) const;
    CellWindow window_;
    std::size_t west_ = 0, east_ = 0, local_ = 0; // ghost slots kept, particles sorted
    std::vector<double> x_, y_, vx_, vy_, rho_, p_over_rho2_, mass_, fluid_, remote_;
    static constexpr std::size_t record_size = 4; // View::records' values per position
    std::vector<PairReal, CacheLineAllocator<PairReal>> records_;
    std::vector<std::uint32_t> orig_, start_, key_, blocks_;
    // sort_by_key's: per thread, its particles per cell, then its next position per cell
    // (thread t's cells at [t x cells, (t + 1) x cells)); the particles of each thread's cells.
    std::vector<std::uint32_t> fill_;
    std::vector<std::size_t> block_sizes_;
    struct alignas(64) Checks {  // update's, per thread: one cache line each
        bool edge = false;       // a particle in an edge column kept for ghosts
        bool other_mass = false; // a mass other than the first particle's
        bool descending = false; // a particle whose id is not below the next one's
    };
    std::vector<Checks> checks_;
    struct alignas(64) FluidCount { // copy_fields', per thread: one cache line each
        std::size_t n = 0;
    };
    std::vector<FluidCount> fluid_count_;
    std::vector<std::size_t> fluid_split_;   // fluid_split()
    std::vector<std::size_t> sort_split_;    // update's particles per thread (empty: equal)
    std::vector<std::uint64_t> cost_;        // cut_blocks': candidates examined in cells [0, c)
    std::vector<std::uint64_t> block_costs_; // cut_blocks': each thread's share of them
    int threads_ = 0;
    std::vector<std::uint32_t> order_, reorder_starts_; // reorder's
    std::vector<std::uint8_t> remote_columns_;
    std::vector<std::uint32_t> fluid_below_;
    int cols_ = 0, rows_ = 0;
    std::size_t owned_ = 0, moves_ = 0;
    double common_mass_ = 0; // View::common_mass
    // remote_ holds zeros only: true after an update with no ghost slots and no particle
    // beyond the owned ones (one rank without mirrors), whose copy then skips writing them.
    bool remote_zero_ = false;
    Sweep sweep_;
};

// The neighbourhood Cell+Sorted supplies to the physics: no stored pairs; the counts of the
// last density pass (every step but the initial force evaluation).
struct SortedNeighbours {
    CellSorted *grid = nullptr;
    PairCounts counts;
};

// Branch-free quintic kernel: the polynomial of QuinticKernel in q = r / h with the absent
// pieces adding exact zeros, and q from one multiplication (no division): equal to rounding
// (tested).
struct BranchFreeKernel {
    double h, inv_h, alpha_d, alpha_d_over_h;
    explicit BranchFreeKernel(const QuinticKernel &k)
        : h(k.h), inv_h(1.0 / k.h), alpha_d(k.alpha_d), alpha_d_over_h(k.alpha_d / k.h) {}
    // T: double or float, or Lanes4 or Lanes8 (the AVX2 pair loops, sorted.cpp).
    // max(v, 0) in the form of the max instructions (v > 0 ? v : 0), which GCC emits for
    // doubles: `v < 0 ? 0 : v` became a compare and a mask (sph/NOTES.md, session 63). For
    // Lanes4 GCC still emitted a compare and a mask, so the instruction is spelt out; it
    // returns its second operand unless the first is greater: the same bits.
    static double pos(double v) { return v > 0.0 ? v : 0.0; }
    static float pos(float v) { return v > 0.0f ? v : 0.0f; }
#if defined(__AVX2__)
    static Lanes4 pos(Lanes4 v) {
        return _mm256_max_pd(v, _mm256_setzero_pd());
    }
    static Lanes8 pos(Lanes8 v) {
        return _mm256_max_ps(v, _mm256_setzero_ps());
    }
#endif
    // W / alpha_d and its slope d(W / alpha_d)/dq.
    static double shape(double q) {
        const double a = pos(3 - q), b = pos(2 - q), c = pos(1 - q);
        double w = a * a * a * a * a;
        w -= 6 * (b * b * b * b * b);
        w += 15 * (c * c * c * c * c);
        return w;
    }
    // s x slope(q) with s folded into the three coefficients (the pair loops fold the kernel's
    // alpha_d / h and, where every particle has one, the mass): two multiplications a pair
    // fewer, the same value to rounding.
    // E: the precision of the coefficients (that of the lanes, double or float).
    template <class E> struct ScaledSlopeOf {
        E a, b, c; // -5 s, 30 s, -75 s
        explicit constexpr ScaledSlopeOf(double s)
            : a(static_cast<E>(-5 * s)), b(static_cast<E>(30 * s)), c(static_cast<E>(-75 * s)) {}
    };
    using ScaledSlope = ScaledSlopeOf<double>;
    template <class T, class E> static T slope(T q, const ScaledSlopeOf<E> &w) {
        const T a = pos(3 - q), b = pos(2 - q), c = pos(1 - q);
        // Fourth powers as squares of squares: two multiplications deep, not three (the pair
        // loops wait on this chain).
        const T a2 = a * a, b2 = b * b, c2 = c * c;
        return w.a * (a2 * a2) + w.b * (b2 * b2) + w.c * (c2 * c2);
    }
    template <class T> static T slope(T q) {
        return slope(q, ScaledSlope(1.0));
    }
    double value(double r) const {
        return alpha_d * shape(r * inv_h);
    }
    double derivative(double r) const {
        return alpha_d_over_h * slope(r * inv_h);
    }
};

// The grid is the neighbourhood: building it is the sort already done by update().
inline void build_neighbours(CellSorted &grid, const Particles &, const CellWindow &, double,
                             SortedNeighbours &nb) {
    nb.grid = &grid;
}

// A grid that can sort before the ghosts arrive and compute by columns (--overlap).
template <class G>
concept OverlapGrid = requires(G g, const G cg, const Particles &p, const CellWindow &w,
                               std::size_t n) {
    g.update(p, w, n, n);
    g.add_ghosts(p, n);
    g.refresh_density(p);
    g.refresh_ghost_density(p);
    { cg.columns_without_ghosts() } -> std::same_as<ColumnSet>;
};

// One particle's candidates within the support, packed in candidate order (columns west to
// east, rows bottom to top, ids within a cell): their sorted positions and separations from
// the particle (computed in double, stored as PairReal), then padding to whole vectors (position
// `self`, separation 0, which every kernel masks out as it masks the particle itself). The force
// and density loops then run over the pairs that interact only: about half of the 3 x (2
// rows_per_cell + 1) / rows_per_cell cells' candidates lie beyond 3h, and the loops are bound by
// their arithmetic, which a masked lane pays in full. Each thread's scratch for one pass (one per
// particle of a cell packed together), grown to its largest neighbourhood and reused for every
// particle.
struct PackedCandidates {
    std::vector<std::uint32_t, CacheLineAllocator<std::uint32_t>> index;
    std::vector<PairReal, CacheLineAllocator<PairReal>> dx, dy;
    std::size_t size = 0;       // packed candidates, without the padding
    std::size_t padded = 0;     // with it: a multiple of the pair loops' vectors (8 or 16 lanes)
    std::uint64_t in_range = 0; // candidates within the support (with those at distance 0)
    std::uint64_t remote = 0;   // of those, the ones this rank does not own
};

// Appends to `out` the candidates at sorted positions [b, e) within distance^2 r2max of
// (xi, yi) and not at it (distance 0: the particle itself, or a coincident image), and only
// fluid ones with `fluid_only`; counts the in-range ones (distance 0 included) and their remote
// share. `out`'s arrays must hold out.size + (e - b) + 8 entries. Vectorised with AVX-512 (or AVX2)
// where the build has it; pack_in_range_portable is the plain loop, the same result (tested).
void pack_in_range(const CellSorted::View &v, double xi, double yi, double r2max, bool fluid_only,
                   std::size_t b, std::size_t e, PackedCandidates &out);
void pack_in_range_portable(const CellSorted::View &v, double xi, double yi, double r2max,
                            bool fluid_only, std::size_t b, std::size_t e, PackedCandidates &out);
// The same for `batch` particles at once (1 to pack_batch_size), at (xi[k], yi[k]) into
// out[k]: the passes pack the particles of one cell together, since they scan the same ranges
// (each vector of candidates loaded and each range's loop run once for all of them: 6 % of the
// dam break's compute on the Zen 3 host of session 65, sph/NOTES.md). Each out[k] as
// pack_in_range for that particle alone leaves it (tested).
inline constexpr int pack_batch_size = 4;
void pack_in_range(const CellSorted::View &v, const double *xi, const double *yi, int batch,
                   double r2max, bool fluid_only, std::size_t b, std::size_t e,
                   PackedCandidates *const *out);

// The three drivers of the physics for Cell+Sorted (physics.hpp has them for stored lists).
void continuity(Particles &p, SortedNeighbours &nb, const Physics &phys, double back = 0);
void momentum(Particles &p, SortedNeighbours &nb, const Physics &phys);
// The first two over the owned particles of some columns only (--overlap); each particle's
// sum is the same as in the whole pass. continuity_columns returns the counts of its
// particles (add the parts up); momentum_columns reads the sorted densities as they are
// (refresh_density first).
struct DensityCounts {
    // Summed over owned i: every pair of two owned particles twice, every pair with a ghost or
    // mirror once; `remote` counts the latter. The pairs are their half-sum.
    std::uint64_t interactions = 0, remote = 0;
    DensityCounts &operator+=(const DensityCounts &o) {
        interactions += o.interactions;
        remote += o.remote;
        return *this;
    }
    PairCounts counts() const { return {(interactions + remote) / 2, interactions}; }
};
DensityCounts continuity_columns(Particles &p, SortedNeighbours &nb, const Physics &phys,
                                 double back, ColumnSet cols);
void momentum_columns(Particles &p, SortedNeighbours &nb, const Physics &phys, ColumnSet cols);
void shepard_filter(Particles &p, SortedNeighbours &nb, const Physics &phys);
// Continuity, the density advance (rho += dt drho, integrator.hpp advance_density), the
// equation of state and the forces in one sweep over the columns, for a rank without mirrors:
// column c's density pass, then its densities and pressures, then the force pass of column
// c - 1, whose neighbours (c - 2 to c) have theirs by then, from the packs its density pass
// kept (the step moves no particle between the passes). The threads take the columns in
// chunks (CellSorted::next_columns); a column whose neighbour another thread sweeps waits for
// its flag, at the end. Every sum is the passes' own: bitwise the same as continuity,
// advance_density, the ghost refresh, equation_of_state and momentum apart (tested), while
// the force pass packs almost nothing and reads what the step just touched.
// sweep_columns sweeps the columns of one range and returns their density pass's counts; it
// holds the force passes of the columns beside ghosts (View::remote_columns) or beside
// columns out of the range, which force_held_columns runs once their neighbours are final.
DensityCounts sweep_columns(Particles &p, SortedNeighbours &nb, const Physics &phys, double back,
                            double dt, ColumnSet columns);
void force_held_columns(Particles &p, SortedNeighbours &nb, const Physics &phys);
// The whole step's: every column swept, then `ghost_densities`, called outside the threads,
// which must bring the ghosts' densities, pressures and sorted copies
// (Domain::refresh_ghost_density, the equation of state, CellSorted::refresh_ghost_density),
// then the held columns.
void sweep_forces(Particles &p, SortedNeighbours &nb, const Physics &phys, double back, double dt,
                  const std::function<void()> &ghost_densities = {});
// The density advance, equation of state and sorted-copy refresh of the owned particles of
// some columns (what the sweep does per column; --overlap's edge columns).
void advance_columns(Particles &p, SortedNeighbours &nb, const Physics &phys, double dt,
                     ColumnSet columns);

// A grid whose neighbourhood has such a sweep (Simulation's compute_forces and
// compute_forces_overlapped use it where they can).
template <class G>
concept SweepingGrid = requires(Particles &p, typename G::Neighbours &nb, const Physics &phys,
                                const std::function<void()> &f, ColumnSet c) {
    sweep_forces(p, nb, phys, 0.0, 0.0, f);
    { sweep_columns(p, nb, phys, 0.0, 0.0, c) } -> std::same_as<DensityCounts>;
    force_held_columns(p, nb, phys);
    advance_columns(p, nb, phys, 0.0, c);
};

} // namespace sphperf::sph
