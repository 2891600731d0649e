#include "sphperf/sph/sorted.hpp"

#include <omp.h>

#if defined(SPHPERF_AVX2_KERNELS) || defined(SPHPERF_AVX512_KERNELS)
#include <immintrin.h>
#endif

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

namespace sphperf::sph {

namespace {

// The calling thread's cells, inside a parallel region: its block, or for a team of another
// size than the blocks were cut for, an equal share of the cells.
std::pair<std::size_t, std::size_t> thread_cells(const std::uint32_t *blocks, int threads,
                                                 std::size_t cells) {
    const int t = omp_get_thread_num(), n = omp_get_num_threads();
    if (n == threads)
        return {blocks[t], blocks[t + 1]};
    const auto share = [&](int k) { return cells * static_cast<std::size_t>(k) / n; };
    return {share(t), share(t + 1)};
}

} // namespace

std::uint32_t CellSorted::key_of(double x, double y) const {
    const double row_height = window_.cell_size / rows_per_cell;
    const int first_row = window_.row_begin * rows_per_cell;
    // Positions outside the window are filed in its edge rows, as CellWindow files them.
    const int row =
        std::clamp(static_cast<int>(std::floor(y / row_height)), first_row, first_row + rows_ - 1) -
        first_row;
    return static_cast<std::uint32_t>((window_.column_of(x) - window_.col_begin) * rows_ + row);
}

// Within each cell of [first_cell, last_cell), by id (a few particles: insertion sort).
void CellSorted::sort_cells_by_id(const Particles &p, std::size_t first_cell,
                                  std::size_t last_cell) {
#pragma omp parallel
    {
        const auto [c0, c1] = thread_cells(blocks_.data(), threads_, start_.size() - 1);
        for (std::size_t c = std::max(c0, first_cell); c < std::min(c1, last_cell); ++c) {
            const auto b = orig_.begin() + start_[c], e = orig_.begin() + start_[c + 1];
            for (auto it = b + (b != e); it < e; ++it)
                for (auto j = it; j > b && p.id[*(j - 1)] > p.id[*j]; --j)
                    std::iter_swap(j - 1, j);
        }
    }
}

void CellSorted::cut_blocks() {
    const int threads = std::max(omp_get_max_threads(), 1);
    const std::size_t cells = start_.size() - 1;
    constexpr int reach = rows_per_cell;
    cost_.resize(start_.size());
    cost_[0] = 0;
    block_costs_.assign(static_cast<std::size_t>(threads) + 1, 0);
    // In parallel (a serial pass over every cell cost 3 % of a 2-thread step): each thread sums
    // its block of the last step (contiguous and in thread order; equal shares of the cells
    // left the threads unbalanced, a dam break's water filling the first ones), then adds the
    // blocks before its own. Integer costs, so the sum is exact whatever the split; empty cells
    // (most of a dam-break tank) cost one compare.
    const bool last_blocks = blocks_.size() == static_cast<std::size_t>(threads) + 1 &&
                             blocks_.back() == cells && threads_ == threads;
#pragma omp parallel num_threads(threads)
    {
        const auto t = static_cast<std::size_t>(omp_get_thread_num());
        const auto [c0, c1] =
            thread_cells(last_blocks ? blocks_.data() : nullptr, last_blocks ? threads : 0, cells);
        std::uint64_t sum = 0;
        // The cell's column and row followed along, not divided out per cell.
        int col = rows_ > 0 ? static_cast<int>(c0) / rows_ : 0;
        int row = rows_ > 0 ? static_cast<int>(c0) % rows_ : 0;
        for (std::size_t cell = c0; cell < c1; ++cell) {
            const std::uint32_t here = start_[cell + 1] - start_[cell];
            if (here != 0) {
                const int r0 = std::max(row - reach, 0), r1 = std::min(row + reach, rows_ - 1);
                std::uint64_t candidates = 0;
                for (int c = std::max(col - 1, 0); c <= std::min(col + 1, cols_ - 1); ++c)
                    candidates += start_[c * rows_ + r1 + 1] - start_[c * rows_ + r0];
                sum += here * candidates;
            }
            cost_[cell + 1] = sum;
            if (++row == rows_) {
                row = 0;
                ++col;
            }
        }
        block_costs_[t + 1] = sum;
#pragma omp barrier
        std::uint64_t before = 0;
        for (std::size_t u = 0; u < t; ++u)
            before += block_costs_[u + 1];
        if (before > 0)
            for (std::size_t cell = c0; cell < c1; ++cell)
                cost_[cell + 1] += before;
    }
    const std::vector<double> shares = thread_shares(threads);
    blocks_.assign(static_cast<std::size_t>(threads) + 1, static_cast<std::uint32_t>(cells));
    blocks_[0] = 0;
    double before = 0;
    for (int t = 1; t < threads; ++t) {
        before += shares[static_cast<std::size_t>(t - 1)];
        const auto target =
            static_cast<std::uint64_t>(std::llround(static_cast<double>(cost_[cells]) * before));
        blocks_[t] = static_cast<std::uint32_t>(
            std::lower_bound(cost_.begin(), cost_.end(), target) - cost_.begin());
    }
    // Each block in chunks of equal cost (start_pass, next_cells).
    chunk_bounds_.resize(static_cast<std::size_t>(threads) * chunks_per_block + 1);
    for (int t = 0; t < threads; ++t) {
        const std::uint64_t c0 = cost_[blocks_[t]], c1 = cost_[blocks_[t + 1]];
        const std::size_t k0 = static_cast<std::size_t>(t) * chunks_per_block;
        chunk_bounds_[k0] = blocks_[t];
        for (int c = 1; c < chunks_per_block; ++c) {
            const std::uint64_t target = c0 + (c1 - c0) * static_cast<std::uint64_t>(c) /
                                                  static_cast<std::uint64_t>(chunks_per_block);
            // The block's first cell whose prefix reaches it (searched within the block:
            // cost_ is flat over empty cells, also before the block's start).
            const auto b0 = cost_.begin() + blocks_[t], b1 = cost_.begin() + blocks_[t + 1];
            chunk_bounds_[k0 + static_cast<std::size_t>(c)] =
                static_cast<std::uint32_t>(std::lower_bound(b0, b1, target) - cost_.begin());
        }
    }
    chunk_bounds_.back() = blocks_[static_cast<std::size_t>(threads)];
    if (queue_count_ != threads) {
        queues_ = std::make_unique<ChunkQueue[]>(static_cast<std::size_t>(threads));
        queue_count_ = threads;
    }
    threads_ = threads;
}

void CellSorted::reset_queues(int per_block) {
    for (int t = 0; t < queue_count_; ++t) {
        const auto first = static_cast<std::uint64_t>(t) * static_cast<std::uint64_t>(per_block);
        queues_[static_cast<std::size_t>(t)].range.store(
            first | (first + static_cast<std::uint64_t>(per_block)) << 32,
            std::memory_order_relaxed);
    }
}

void CellSorted::start_pass() {
    reset_queues(chunks_per_block);
}

bool CellSorted::next_cells(int thread, std::uint32_t &first, std::uint32_t &last) {
    return take_chunk(chunk_bounds_, thread, first, last);
}

int CellSorted::column_nearest(std::size_t cell) const {
    if (rows_ <= 0)
        return 0;
    const auto rows = static_cast<std::size_t>(rows_);
    return std::min(static_cast<int>((cell + rows / 2) / rows), cols_);
}

void CellSorted::start_sweep() {
    const auto rows = static_cast<std::uint32_t>(rows_);
    const auto column_of_block = [&](int t) {
        return column_nearest(blocks_[static_cast<std::size_t>(std::min(t, threads_))]);
    };
    constexpr auto per_block = static_cast<std::size_t>(column_chunks_per_block);
    // Chunk c starts where a fraction 1 - (3/5)^c of the block's cost lies before it (in units
    // of 2^-20, exact integers): large chunks first and small ones at the back, where another
    // thread that ran out takes them, so the threads end close together. Equal chunks left the
    // last thread running alone for half a chunk, 4-5 % of the sweep at 2 threads.
    constexpr std::uint64_t one = 1 << 20;
    constexpr std::array<std::uint64_t, per_block> before = [] {
        std::array<std::uint64_t, per_block> f{};
        std::uint64_t left = one;
        for (auto &x : f) {
            x = one - left;
            left = left * 3 / 5;
        }
        return f;
    }();
    column_bounds_.resize(static_cast<std::size_t>(threads_) * per_block + 1);
    for (int t = 0; t < threads_; ++t) {
        const int a = column_of_block(t), b = std::max(column_of_block(t + 1), a);
        const auto cost_at = [&](int col) { return cost_[static_cast<std::size_t>(col) * rows]; };
        const std::uint64_t c0 = cost_at(a), c1 = cost_at(b);
        const std::size_t k0 = static_cast<std::size_t>(t) * per_block;
        int col = a;
        for (std::size_t c = 0; c < per_block; ++c) {
            // The first column whose prefix reaches the chunk's share (cost_ is a prefix sum).
            const std::uint64_t target = c0 + (c1 - c0) * before[c] / one;
            while (col < b && cost_at(col) < target)
                ++col;
            column_bounds_[k0 + c] = static_cast<std::uint32_t>(c == 0 ? a : col);
        }
    }
    column_bounds_.back() = static_cast<std::uint32_t>(cols_);
    reset_queues(column_chunks_per_block);
}

bool CellSorted::next_columns(int thread, std::uint32_t &first, std::uint32_t &last) {
    return take_chunk(column_bounds_, thread, first, last, sweep_from_back);
}

bool CellSorted::take_chunk(const std::vector<std::uint32_t> &bounds, int thread,
                            std::uint32_t &first, std::uint32_t &last, bool own_from_back) {
    // Takes chunk [front] (own == true) or [back - 1] of a queue; false when it is empty.
    auto take = [&](int t, bool own) {
        own = own && !own_from_back;
        std::atomic<std::uint64_t> &q = queues_[static_cast<std::size_t>(t)].range;
        std::uint64_t r = q.load(std::memory_order_relaxed);
        for (;;) {
            const std::uint64_t front = r & 0xffffffffu, back = r >> 32;
            if (front >= back)
                return false;
            const std::uint64_t next = own ? (front + 1) | back << 32 : front | (back - 1) << 32;
            if (q.compare_exchange_weak(r, next, std::memory_order_acq_rel,
                                        std::memory_order_relaxed)) {
                const std::size_t k = own ? front : back - 1;
                first = bounds[k];
                last = bounds[k + 1];
                return true;
            }
        }
    };
    if (take(thread, true))
        return true;
    for (int d = 1; d < queue_count_; ++d)
        if (take((thread + d) % queue_count_, false))
            return true;
    return false;
}

std::vector<double> CellSorted::thread_shares(int threads) {
    const auto n = static_cast<std::size_t>(threads);
    // The last step's blocks: their cost and the time each thread spent on them in the pair
    // passes give its seconds per unit of cost, smoothed over about 1 / speed_smoothing steps.
    if (threads == threads_ && pass_time_.size() == n) {
        if (seconds_per_cost_.size() != n)
            seconds_per_cost_.assign(n, 0.0);
        for (std::size_t t = 0; t < n; ++t) {
            // The cells it went through, its own block's and what it took of the others'.
            const double seconds = pass_time_[t].seconds, cost = pass_time_[t].cost;
            if (!(cost > 0) || !(seconds > 0))
                continue;
            const double rate = seconds / cost;
            double &r = seconds_per_cost_[t];
            r = r > 0 ? r + speed_smoothing * (rate - r) : rate;
        }
    } else {
        seconds_per_cost_.clear();
    }
    pass_time_.assign(n, PassTime{});
    // A thread that got through its cost faster gets more of it: shares in proportion to the
    // inverse rates, equal until every thread has one.
    std::vector<double> shares(n, 1.0 / static_cast<double>(n));
    if (seconds_per_cost_.size() == n &&
        std::all_of(seconds_per_cost_.begin(), seconds_per_cost_.end(),
                    [](double r) { return r > 0; })) {
        double sum = 0;
        for (std::size_t t = 0; t < n; ++t)
            sum += shares[t] = 1.0 / seconds_per_cost_[t];
        for (double &sh : shares)
            sh /= sum;
    }
    return shares;
}

std::pair<std::size_t, std::size_t> CellSorted::thread_positions() const {
    const std::size_t cells = start_.size() - 1;
    const auto [c0, c1] = thread_cells(blocks_.data(), threads_, cells);
    // The first and last threads also take the positions outside every cell's range.
    return {c0 == 0 ? 0 : start_[c0], c1 == cells ? orig_.size() : start_[c1]};
}

void CellSorted::copy_fields(const Particles &p, std::size_t from, std::size_t to, int first_column,
                             int last_column, bool count_fluid, bool remote_flags) {
    const auto rows = static_cast<std::size_t>(rows_);
    remote_columns_.resize(static_cast<std::size_t>(cols_));
    fluid_below_.resize(static_cast<std::size_t>(cols_) * (rows + 1));
    // One parallel region for both (a region more per step costs a wake-up of the team).
    const std::size_t fluid_end = count_fluid ? p.fluid() : 0; // owned fluid: [0, fluid_end)
    // Only what the passes read (View): the masses where they differ, the velocities where
    // the pair loops take them from here rather than from the records.
    const bool masses = common_mass_ == 0;
    if (count_fluid)
        fluid_count_.assign(static_cast<std::size_t>(std::max(omp_get_max_threads(), 1)),
                            FluidCount{});
#pragma omp parallel
    {
        const auto [s0, s1] = thread_positions();
        std::size_t owned_fluid = 0;
        for (std::size_t s = std::max(s0, from); s < std::min(s1, to); ++s) {
            const std::uint32_t i = orig_[s];
            owned_fluid += i < fluid_end;
            x_[s] = p.x[i];
            y_[s] = p.y[i];
            if constexpr (pair_records) {
                records_[record_size * s] = static_cast<PairReal>(p.vx[i]);
                records_[record_size * s + 1] = static_cast<PairReal>(p.vy[i]);
            } else {
                vx_[s] = p.vx[i];
                vy_[s] = p.vy[i];
            }
            if (masses)
                mass_[s] = p.mass[i];
            // Stored only where it changed (few positions change kind between steps): a store
            // to a line out of L2 is what the far mode charges (sph/NOTES.md, session 88).
            if (const double wet = p.kind[i] == Kind::fluid ? 1.0 : 0.0; fluid_[s] != wet)
                fluid_[s] = wet;
            if (remote_flags)
                if (const double far = i < owned_ ? 0.0 : 1.0; remote_[s] != far)
                    remote_[s] = far;
        }
        if (const auto t = static_cast<std::size_t>(omp_get_thread_num());
            count_fluid && t < fluid_count_.size())
            fluid_count_[t].n = owned_fluid;
#pragma omp barrier
        // This thread's block rounded to whole columns, as the sweep takes them: about the
        // positions it just copied, and as balanced as the blocks (a static split of the
        // columns gave one thread the whole water of a dam break: 0.23 against 0.09 ms at
        // scale 4).
        const auto [c0, c1] = thread_cells(blocks_.data(), threads_, start_.size() - 1);
        const auto column_from = [&](std::size_t cell) {
            return std::clamp(column_nearest(cell), first_column, last_column);
        };
        for (int col = column_from(c0); col < column_from(c1); ++col) {
            const auto c = static_cast<std::size_t>(col);
            std::uint32_t *below = fluid_below_.data() + c * (rows + 1);
            std::uint32_t fluid = 0;
            bool remote = false;
            for (std::size_t r = 0; r < rows; ++r) {
                below[r] = fluid;
                for (std::size_t s = start_[c * rows + r]; s < start_[c * rows + r + 1]; ++s) {
                    fluid += fluid_[s] > 0;
                    remote |= remote_flags && remote_[s] > 0;
                }
            }
            below[rows] = fluid;
            remote_columns_[c] = remote;
        }
    }
}

void CellSorted::set_window(const CellWindow &w) {
    window_ = w;
    cols_ = w.cols();
    rows_ = w.rows() * rows_per_cell;
}

void CellSorted::prepare_sort(int threads, std::vector<std::uint32_t> &starts) {
    const auto cells = static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_);
    starts.resize(cells + 1);
    // sort_by_key leaves every entry 0; a new size starts from 0 too.
    if (fill_.size() != static_cast<std::size_t>(threads) * cells)
        fill_.assign(static_cast<std::size_t>(threads) * cells, 0);
    block_sizes_.resize(static_cast<std::size_t>(threads));
}

void CellSorted::sort_by_key(std::size_t first, std::size_t last, std::size_t base,
                             std::vector<std::uint32_t> &starts, std::vector<std::uint32_t> &out,
                             std::span<const std::size_t> split,
                             std::span<const std::uint32_t> cuts) {
    // Each thread counts its share of the particles into its own histogram, the offsets are
    // summed over shares of the cells, and each thread files its share. Within a cell the
    // threads' shares follow in thread order, so the result is the serial stable sort's. (Each
    // thread scanning every key for its block of cells took as long at 2 threads as at 1.)
    const auto cells = static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_);
    const auto t = static_cast<std::size_t>(omp_get_thread_num());
    const auto team = static_cast<std::size_t>(omp_get_num_threads());
    const std::size_t n = last - first;
    const bool by_split = split.size() == team + 1 && split.back() == n;
    const bool by_cuts = cuts.size() == team + 1 && cuts.back() == cells;
    const std::size_t i0 = first + (by_split ? split[t] : n * t / team),
                      i1 = first + (by_split ? split[t + 1] : n * (t + 1) / team);
    const std::size_t c0 = by_cuts ? cuts[t] : cells * t / team,
                      c1 = by_cuts ? cuts[t + 1] : cells * (t + 1) / team;
    std::uint32_t *const mine = fill_.data() + t * cells;
    const std::uint32_t *const keys = key_.data();
    // The histograms are 0 on entry (prepare_sort, and each thread clears what it used below):
    // no pass writes a line of cells its particles do not touch.
    for (std::size_t i = i0; i < i1; ++i)
        ++mine[keys[i]];
#pragma omp barrier
    std::size_t size = 0;
    for (std::size_t u = 0; u < team; ++u)
        for (std::size_t c = c0; c < c1; ++c)
            size += fill_[u * cells + c];
    block_sizes_[t] = size;
#pragma omp barrier
    std::size_t at = base;
    for (std::size_t u = 0; u < t; ++u)
        at += block_sizes_[u];
    // In runs of cells: most of a tank is empty, and a run whose histograms are all 0 is only
    // its starts (a branch per cell and thread cost about 2 ns a cell, 12 us of a 2-thread step
    // at scale 1 on the thread with the dry cells).
    constexpr std::size_t run = 16;
    for (std::size_t r0 = c0; r0 < c1; r0 += run) {
        const std::size_t r1 = std::min(r0 + run, c1);
        std::uint32_t any = 0;
        for (std::size_t u = 0; u < team; ++u)
            for (std::size_t c = r0; c < r1; ++c)
                any |= fill_[u * cells + c];
        if (any == 0) {
            std::fill(starts.begin() + static_cast<std::ptrdiff_t>(r0),
                      starts.begin() + static_cast<std::ptrdiff_t>(r1),
                      static_cast<std::uint32_t>(at));
            continue;
        }
        for (std::size_t c = r0; c < r1; ++c) {
            starts[c] = static_cast<std::uint32_t>(at);
            for (std::size_t u = 0; u < team; ++u)
                if (const std::uint32_t k = fill_[u * cells + c]; k != 0) {
                    fill_[u * cells + c] = static_cast<std::uint32_t>(at);
                    at += k;
                }
        }
    }
    if (t + 1 == team)
        starts[cells] = static_cast<std::uint32_t>(at);
#pragma omp barrier
    for (std::size_t i = i0; i < i1; ++i)
        out[mine[keys[i]]++] = static_cast<std::uint32_t>(i);
    for (std::size_t i = i0; i < i1; ++i)
        mine[keys[i]] = 0;
}

void CellSorted::reorder(Particles &p, const CellWindow &w) {
    set_window(w);
    key_.resize(p.owned());
    for (std::size_t i = 0; i < p.owned(); ++i)
        key_[i] = key_of(p.x[i], p.y[i]);
    order_.resize(p.owned());
    const int threads = std::max(omp_get_max_threads(), 1);
    prepare_sort(threads, reorder_starts_);
    // The fluid, then the walls after them (Particles keeps them apart).
#pragma omp parallel num_threads(threads)
    {
        sort_by_key(0, p.fluid(), 0, reorder_starts_, order_);
#pragma omp barrier
        sort_by_key(p.fluid(), p.owned(), p.fluid(), reorder_starts_, order_);
    }
    p.permute(order_);
}

void CellSorted::update(const Particles &p, const CellWindow &w, std::size_t west,
                        std::size_t east) {
    const std::size_t n = p.size();
    set_window(w);
    west_ = west;
    east_ = east;
    local_ = n;
    const auto cells = static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_);
    const auto last_column = cells - static_cast<std::size_t>(rows_);
    owned_ = p.owned();
    key_.resize(n);
    const double mass = n > 0 ? p.mass[0] : 0.0;
    // Counting sort by cell, then by id within a cell. The west ghosts' slots come first: every
    // cell starts `west` positions later, and the edge columns kept for ghosts stay empty until
    // add_ghosts (sort_by_key writes every other position).
    orig_.resize(n + west + east);
    std::fill(orig_.begin(), orig_.begin() + static_cast<std::ptrdiff_t>(west), 0);
    std::fill(orig_.begin() + static_cast<std::ptrdiff_t>(west + n), orig_.end(), 0);
    const int threads = std::max(omp_get_max_threads(), 1);
    prepare_sort(threads, start_);
    checks_.assign(static_cast<std::size_t>(threads), Checks{});
    const auto edge_rows = static_cast<std::uint32_t>(west > 0 ? rows_ : 0);
    const auto east_edge = static_cast<std::uint32_t>(east > 0 ? last_column : cells);
    // The threads' particles: the last update's fluid split where it still fits (the fluid by
    // the blocks' cells, the walls and any transient with the last thread), so that keys,
    // counts and filing stay on the core of the cells, as the blocks of the last cut do for the
    // offsets; else equal shares.
    sort_split_.clear();
    if (fluid_split_.size() == static_cast<std::size_t>(threads) + 1 &&
        fluid_split_.back() == p.fluid()) {
        sort_split_ = fluid_split_;
        sort_split_.back() = n;
    }
    const bool cut = blocks_.size() == static_cast<std::size_t>(threads) + 1 &&
                     blocks_.back() == cells && threads_ == threads;
    const std::span<const std::uint32_t> cuts =
        cut ? std::span<const std::uint32_t>(blocks_) : std::span<const std::uint32_t>{};
    // One region for the keys and the sort (a region more per step costs a wake-up of the team).
#pragma omp parallel num_threads(threads)
    {
        const auto t = static_cast<std::size_t>(omp_get_thread_num());
        const auto team = static_cast<std::size_t>(omp_get_num_threads());
        const bool by_split = sort_split_.size() == team + 1;
        const std::size_t i0 = by_split ? sort_split_[t] : n * t / team,
                          i1 = by_split ? sort_split_[t + 1] : n * (t + 1) / team;
        // The keys, then the checks as flags: both loops vectorise.
        for (std::size_t i = i0; i < i1; ++i)
            key_[i] = key_of(p.x[i], p.y[i]);
        unsigned edge = 0, other_mass = 0, descending = 0;
        for (std::size_t i = i0; i < i1; ++i) {
            edge |= static_cast<unsigned>(key_[i] < edge_rows) | (key_[i] >= east_edge);
            other_mass |= static_cast<unsigned>(p.mass[i] != mass);
        }
        for (std::size_t i = i0; i < std::min(i1, n - 1); ++i)
            descending |= static_cast<unsigned>(p.id[i] >= p.id[i + 1]);
        checks_[t] = {edge != 0, other_mass != 0, descending != 0};
        sort_by_key(0, n, west, start_, orig_, sort_split_, cuts);
    }
    Checks all;
    for (const Checks &c : checks_) {
        all.edge = all.edge || c.edge;
        all.other_mass = all.other_mass || c.other_mass;
        all.descending = all.descending || c.descending;
    }
    common_mass_ = all.other_mass ? 0.0 : mass;
    if (all.edge)
        for (std::size_t i = 0; i < n; ++i)
            if (key_[i] < edge_rows || key_[i] >= east_edge)
                throw std::logic_error("sorted grid: particle " + std::to_string(p.id[i]) +
                                       " sits in an edge column kept for ghosts");
    cut_blocks();
    // The sort is stable: where the particles are in id order (one rank's, as the setup made
    // them), so is every cell.
    if (all.descending)
        sort_cells_by_id(p, 0, cells);
    for (auto *v : {&x_, &y_, &rho_, &fluid_, &remote_})
        v->resize(n + west + east);
    // The sorted velocities and masses only where a pass reads them (copy_fields): with one
    // mass and the pair records, 24 bytes a particle fewer to write every step. Writing the
    // sorted copy is what the vCPUs' far mode charges (sph/NOTES.md, session 87).
    if constexpr (pair_records)
        records_.resize(record_size * (n + west + east));
    else
        for (auto *v : {&vx_, &vy_, &p_over_rho2_})
            v->resize(n + west + east);
    if (common_mass_ == 0)
        mass_.resize(n + west + east);
    // One rank without mirrors: no position is remote, and after the first step remote_
    // holds zeros (resize adds zeros), so 8 bytes a particle fewer to write.
    const bool none_remote = owned_ == n && west == 0 && east == 0;
    copy_fields(p, west, west + n, 0, cols_, true, !(none_remote && remote_zero_));
    remote_zero_ = none_remote;
    fluid_split_.assign(1, 0);
    for (const FluidCount &c : fluid_count_)
        fluid_split_.push_back(fluid_split_.back() + c.n);
    moves_ = n + west + east; // every particle is filed anew each step
    // Density and pressure are copied by refresh_density once they are final for the pass
    // that reads them (the density pass reads neither).
}

void CellSorted::add_ghosts(const Particles &p, std::size_t first) {
    const std::size_t n = p.size();
    if (n - first != west_ + east_)
        throw std::logic_error("sorted grid: " + std::to_string(n - first) +
                               " ghosts arrived, slots were kept for " +
                               std::to_string(west_ + east_));
    const auto rows = static_cast<std::size_t>(rows_);
    const auto cells = static_cast<std::size_t>(cols_) * rows;
    const std::size_t base[2] = {0, west_ + local_}; // the west and east blocks
    const std::size_t cell0[2] = {0, cells - rows};
    // Per block: members per row, then positions (cells of a column are its rows).
    std::vector<std::uint32_t> count[2] = {std::vector<std::uint32_t>(rows + 1, 0),
                                           std::vector<std::uint32_t>(rows + 1, 0)};
    key_.resize(n);
    for (std::size_t i = first; i < n; ++i) {
        if (p.mass[i] != common_mass_)
            common_mass_ = 0;
        const std::uint32_t k = key_[i] = key_of(p.x[i], p.y[i]);
        const int b = k < rows ? 0 : (k >= cell0[1] ? 1 : -1);
        if (b < 0 || (b == 0) != (i < first + west_))
            throw std::logic_error("sorted grid: ghost " + std::to_string(p.id[i]) +
                                   " lands outside its edge column");
        ++count[b][k - cell0[b] + 1];
    }
    // A side without ghosts keeps its column as update() filed it (walls, mirrors).
    const std::size_t slots[2] = {west_, east_};
    for (int b = 0; b < 2; ++b) {
        for (std::size_t r = 0; r < rows; ++r)
            count[b][r + 1] += count[b][r];
        if (slots[b] > 0)
            for (std::size_t r = 0; r <= rows; ++r)
                start_[cell0[b] + r] = static_cast<std::uint32_t>(base[b] + count[b][r]);
    }
    for (std::size_t i = first; i < n; ++i) {
        const std::uint32_t k = key_[i];
        const int b = k < rows ? 0 : 1;
        orig_[base[b] + count[b][k - cell0[b]]++] = static_cast<std::uint32_t>(i);
    }
    if (west_ > 0)
        sort_cells_by_id(p, 0, rows);
    if (east_ > 0)
        sort_cells_by_id(p, cells - rows, cells);
    // Only the edge columns changed.
    remote_zero_ = false;
    copy_fields(p, 0, west_, 0, 1);
    copy_fields(p, west_ + local_, west_ + local_ + east_, cols_ - 1, cols_);
}

void CellSorted::refresh_filter_fields(const Particles &p) {
    const bool masses = common_mass_ != 0; // else copy_fields keeps them
    if (masses)
        mass_.resize(orig_.size());
#pragma omp parallel
    {
        const auto [s0, s1] = thread_positions();
        for (std::size_t s = s0; s < s1; ++s)
            rho_[s] = p.rho[orig_[s]];
        if (masses)
            for (std::size_t s = s0; s < s1; ++s)
                mass_[s] = p.mass[orig_[s]];
    }
}

void CellSorted::refresh_density(const Particles &p) {
#pragma omp parallel
    {
        const auto [s0, s1] = thread_positions();
        refresh_density(p, s0, s1);
    }
}

void CellSorted::refresh_ghost_density(const Particles &p) {
    if (west_ > 0 || east_ > 0) { // --overlap: the slots kept at the two ends
        refresh_density(p, 0, west_);
        refresh_density(p, west_ + local_, west_ + local_ + east_);
        return;
    }
    const auto rows = static_cast<std::size_t>(rows_);
    for (std::size_t col = 0; col < static_cast<std::size_t>(cols_); ++col)
        if (remote_columns_[col] != 0) // sorted among the others: their whole columns
            refresh_density(p, start_[col * rows], start_[(col + 1) * rows]);
}

void CellSorted::refresh_density(const Particles &p, std::size_t from, std::size_t to) {
    // Only what the pair loops read: with the records 16 bytes a particle fewer to write every
    // step than the doubles too (sph/NOTES.md, session 88).
    for (std::size_t s = from; s < to; ++s) {
        const double rho = p.rho[orig_[s]];
        const double p_over_rho2 = p.p[orig_[s]] / (rho * rho);
        if constexpr (pair_records) {
            records_[record_size * s + 2] = static_cast<PairReal>(rho);
            records_[record_size * s + 3] = static_cast<PairReal>(p_over_rho2);
        } else {
            rho_[s] = rho;
            p_over_rho2_[s] = p_over_rho2;
        }
    }
}

CellSorted::View CellSorted::view() const {
    return {x_.data(),
            y_.data(),
            vx_.data(),
            vy_.data(),
            rho_.data(),
            p_over_rho2_.data(),
            mass_.data(),
            fluid_.data(),
            remote_.data(),
            pair_records ? records_.data() : nullptr,
            orig_.data(),
            start_.data(),
            cols_,
            rows_,
            owned_,
            blocks_.data(),
            threads_,
            cost_.data(),
            remote_columns_.data(),
            fluid_below_.data(),
            common_mass_};
}

namespace {

// Added to squared distances before the square root (below their rounding unit, so it changes
// no distance but 0, and pairs at distance 0 are masked out):
// every lane then computes finite terms and no arithmetic is conditional.
constexpr double tiny = 1e-150;
// The same in the pair terms' precision (float: above its smallest normal, 1.2e-38).
template <class E> constexpr E tiny_of = static_cast<E>(std::is_same_v<E, float> ? 1e-30 : tiny);

// Lanes of the sums, fixed so that they do not depend on the ISA. Shepard's range loops: one
// AVX-512 vector of doubles. The packed pair loops: 16, two vectors' worth of independent pairs
// in flight per iteration. Each pair's square root, division and kernel polynomial form a long
// dependency chain and a particle's loop runs only 3-6 iterations, so the loops wait on latency:
// in-process alternation (sph/NOTES.md, session 48) put 16 lanes at 0.87-0.97 of 8's time in
// the density pass and 0.93-1.01 in the forces; 4 lanes took 1.19, 32 1.04-1.14 (density).
constexpr int lanes = 8;
constexpr int pair_lanes = 16;
// The packed lists are padded to whole vectors of the pair loops: 16 lanes for the compiler's
// loops, a group of eight for the AVX2 ones (which run the last block's group of eight if it
// holds a candidate: a half group of four for the rest measured 1.05x slower, session 67).
constexpr int pad_lanes = pair_records ? 8 : pair_lanes;

// A sum split over a fixed number of lanes by position within each range (or packed list),
// then added in a fixed tree (neighbours pairwise): deterministic for given range contents, and
// the inner loop vectorises.
template <int N, class E = double> struct LaneSumOf {
    static_assert(N > 0 && (N & (N - 1)) == 0, "a power of two");
    E v[N] = {};
    E total() const {
        std::array<E, N> t;
        std::copy(std::begin(v), std::end(v), t.begin());
        for (int n = N; n > 1; n /= 2)
            for (int k = 0; k < n / 2; ++k)
                t[k] = t[2 * k] + t[2 * k + 1];
        return t[0];
    }
};
using LaneSum = LaneSumOf<lanes>;
using PairSum = LaneSumOf<pair_lanes, PairReal>;

// Calls body(s, lane) for every sorted position s of the 3 x 3 cells around cell (col, row):
// columns west to east, each one contiguous range (cells are numbered column by column).
template <class Body>
void for_each_candidate(const CellSorted::View &v, int col, int row, Body &&body) {
    constexpr int reach = CellSorted::rows_per_cell; // rows within 3h
    const int r0 = std::max(row - reach, 0), r1 = std::min(row + reach, v.rows - 1);
    for (int c = std::max(col - 1, 0); c <= std::min(col + 1, v.cols - 1); ++c) {
        // 64-bit positions: a 32-bit s + l may wrap, and the compiler would then gather
        // element by element instead of loading a vector.
        std::size_t s = v.start[c * v.rows + r0];
        const std::size_t e = v.start[c * v.rows + r1 + 1];
        for (; s + lanes <= e; s += lanes) {
#pragma omp simd
            for (int l = 0; l < lanes; ++l)
                body(s + static_cast<std::size_t>(l), l);
        }
        for (int l = 0; s < e; ++s, ++l)
            body(s, l);
    }
}

// What a pack counts besides packing: nothing (the forces), the in-range candidates (the
// density pass, whose counts are the run's pair counts), or also their remote share (the same
// in a column that holds particles this rank does not own); and whether only fluid candidates
// interact (a wall particle's density pass).
enum class Counted { no, in_range, remote };
enum class Partners { all, fluid };

template <Counted count, Partners partners>
void pack_range_portable(const CellSorted::View &v, double xi, double yi, double r2max,
                         std::size_t b, std::size_t e, PackedCandidates &out) {
    // Local pointers: the stores below could otherwise alias the vectors' and the view's own.
    const double *x = v.x, *y = v.y, *fluid = v.fluid, *far = v.remote;
    std::uint32_t *index = out.index.data();
    PairReal *sx = out.dx.data(), *sy = out.dy.data();
    std::size_t n = out.size;
    std::uint64_t in_range = 0, remote = 0;
    for (std::size_t j = b; j < e; ++j) {
        const double dx = xi - x[j], dy = yi - y[j];
        const double d2 = dx * dx + dy * dy;
        const bool in = d2 < r2max && (partners == Partners::all || fluid[j] > 0);
        if constexpr (count != Counted::no)
            in_range += in;
        if constexpr (count == Counted::remote)
            remote += in && far[j] > 0;
        // Written always, kept by advancing: no branch on the distance.
        index[n] = static_cast<std::uint32_t>(j);
        sx[n] = static_cast<PairReal>(dx);
        sy[n] = static_cast<PairReal>(dy);
        n += in && d2 > 0;
    }
    out.size = n;
    out.in_range += in_range;
    out.remote += remote;
}

#if defined(SPHPERF_AVX512_KERNELS)
// The sum of the eight lanes. Not _mm512_reduce_add_epi64: GCC 12's header builds it on an
// undefined register and warns (-Wuninitialized, GCC bug 105593) in every unit inlining it.
std::uint64_t lane_sum(__m512i v) {
    alignas(64) std::array<std::int64_t, 8> lane;
    _mm512_store_si512(lane.data(), v);
    std::int64_t sum = 0;
    for (std::int64_t x : lane)
        sum += x;
    return static_cast<std::uint64_t>(sum);
}
#endif

#if defined(SPHPERF_AVX2_KERNELS)
// The tables of the AVX2 packing, by the 4-bit mask of the lanes kept: the kept lanes' numbers
// in order (then zeros), which move both the indices and the separations (as floats,
// _mm_permutevar_ps); and the load masks of a tail of 0-4 lanes.
struct alignas(16) Compress4Entry {
    __m128i lanes;
};
struct Compress4 {
    Compress4Entry kept[16];
    __m256i tail[5];
    Compress4() {
        for (int mask = 0; mask < 16; ++mask) {
            alignas(16) std::array<std::int32_t, 4> lane{};
            int kept_lanes = 0;
            for (int l = 0; l < 4; ++l)
                if (mask & (1 << l))
                    lane[kept_lanes++] = l;
            kept[mask].lanes = _mm_load_si128(reinterpret_cast<const __m128i *>(lane.data()));
        }
        for (int left = 0; left <= 4; ++left) {
            alignas(32) std::array<std::int64_t, 4> on{};
            for (int l = 0; l < left; ++l)
                on[l] = -1;
            tail[left] = _mm256_load_si256(reinterpret_cast<const __m256i *>(on.data()));
        }
    }
};
const Compress4 compress4;
#endif

#if defined(SPHPERF_AVX2_KERNELS)
// AVX2 has no compress: four candidates at a time, their kept lanes moved to the front by a
// permutation looked up by the 4-bit mask and stored whole (the next store overwrites the
// rest), the tail by masked loads. On a Zen 3 host the plain loop held about 40 % of the
// density pass's samples; this one runs the dam break 1.36x as fast (sph/NOTES.md, session 60).
// K particles at (xi[k], yi[k]) at once, into out[k]: the particles of one cell scan the same
// ranges, so each vector of candidates is loaded, and each loop exit taken, once for all K.
template <Counted count, Partners partners, int K>
[[gnu::always_inline]] inline void pack_range_avx2(const CellSorted::View &v, const double *xi,
                                                   const double *yi, double r2max, std::size_t b,
                                                   std::size_t e, PackedCandidates *const *out) {
    const double *x = v.x, *y = v.y, *fluid = v.fluid, *far = v.remote;
    const __m256d r2 = _mm256_set1_pd(r2max), zero = _mm256_setzero_pd();
    __m256d x0[K], y0[K];
    // Local pointers: the stores below could otherwise alias the vectors' own.
    std::uint32_t *index[K];
    PairReal *sx[K], *sy[K];
    std::size_t n[K];
    std::uint64_t in_range[K], remote[K];
#pragma GCC unroll 8
    for (int k = 0; k < K; ++k) {
        x0[k] = _mm256_set1_pd(xi[k]);
        y0[k] = _mm256_set1_pd(yi[k]);
        index[k] = out[k]->index.data();
        sx[k] = out[k]->dx.data();
        sy[k] = out[k]->dy.data();
        n[k] = out[k]->size;
        in_range[k] = remote[k] = 0;
    }
    // The positions of the four candidates, stepped by a vector add.
    __m128i position = _mm_set1_epi32(static_cast<int>(b));
    const __m128i four = _mm_set1_epi32(4);
    // Whole vectors, then the tail (masked loads, `valid` its lanes) once, and one table entry
    // per mask: 25 instructions a vector where a tail test in every one compiled to 37. Only
    // about 2 % of the run (sph/NOTES.md, session 64): the packing does not wait on its
    // instruction count.
    const auto four_candidates = [&](std::size_t j, auto load, unsigned valid)
        __attribute__((always_inline)) {
        const __m256d xj = load(x + j), yj = load(y + j);
        __m256d wet{};
        if constexpr (partners == Partners::fluid)
            wet = _mm256_cmp_pd(load(fluid + j), zero, _CMP_GT_OQ);
        unsigned far_bits = 0;
        if constexpr (count == Counted::remote)
            far_bits = static_cast<unsigned>(
                _mm256_movemask_pd(_mm256_cmp_pd(load(far + j), zero, _CMP_GT_OQ)));
#pragma GCC unroll 8
        for (int k = 0; k < K; ++k) {
            const __m256d dx = _mm256_sub_pd(x0[k], xj), dy = _mm256_sub_pd(y0[k], yj);
            const __m256d d2 = _mm256_fmadd_pd(dy, dy, _mm256_mul_pd(dx, dx));
            __m256d in = _mm256_cmp_pd(d2, r2, _CMP_LT_OQ);
            if constexpr (partners == Partners::fluid)
                in = _mm256_and_pd(in, wet);
            if constexpr (count != Counted::no) {
                const unsigned in_bits = static_cast<unsigned>(_mm256_movemask_pd(in)) & valid;
                in_range[k] += static_cast<unsigned>(std::popcount(in_bits));
                if constexpr (count == Counted::remote)
                    remote[k] += static_cast<unsigned>(std::popcount(in_bits & far_bits));
            }
            const unsigned keep = static_cast<unsigned>(_mm256_movemask_pd(
                                      _mm256_and_pd(in, _mm256_cmp_pd(d2, zero, _CMP_GT_OQ)))) &
                                  valid;
            const Compress4Entry &move = compress4.kept[keep];
            _mm_storeu_ps(sx[k] + n[k], _mm_permutevar_ps(_mm256_cvtpd_ps(dx), move.lanes));
            _mm_storeu_ps(sy[k] + n[k], _mm_permutevar_ps(_mm256_cvtpd_ps(dy), move.lanes));
            _mm_storeu_si128(reinterpret_cast<__m128i *>(index[k] + n[k]),
                             _mm_add_epi32(position, move.lanes));
            n[k] += static_cast<std::size_t>(std::popcount(keep));
        }
        position = _mm_add_epi32(position, four);
    };
    std::size_t j = b;
    for (; j + 4 <= e; j += 4)
        four_candidates(
            j, [](const double *a) { return _mm256_loadu_pd(a); }, 0xfu);
    if (j < e) {
        const std::size_t left = e - j;
        const __m256i mask = compress4.tail[left];
        four_candidates(
            j, [mask](const double *a) { return _mm256_maskload_pd(a, mask); }, (1u << left) - 1);
    }
#pragma GCC unroll 8
    for (int k = 0; k < K; ++k) {
        out[k]->size = n[k];
        out[k]->in_range += in_range[k];
        out[k]->remote += remote[k];
    }
}
#endif

template <Counted count, Partners partners>
void pack_range(const CellSorted::View &v, double xi, double yi, double r2max, std::size_t b,
                std::size_t e, PackedCandidates &out) {
#if defined(SPHPERF_AVX512_KERNELS)
    // Eight candidates at a time: the kept lanes compressed to the front of a register and
    // stored whole (the next store overwrites the rest), the tail by masked loads; counts in
    // vector lanes, added up once. GCC 12 vectorises neither the compression nor the tail.
    const double *x = v.x, *y = v.y, *fluid = v.fluid, *far = v.remote;
    std::uint32_t *index = out.index.data();
    PairReal *sx = out.dx.data(), *sy = out.dy.data();
    const __m512d x0 = _mm512_set1_pd(xi), y0 = _mm512_set1_pd(yi), r2 = _mm512_set1_pd(r2max),
                  zero = _mm512_setzero_pd();
    const __m512i one = _mm512_set1_epi64(1);
    // The in-range count is the packed ones plus those at distance 0 (the particle itself).
    __m512i at_zero = _mm512_setzero_si512(), remote = _mm512_setzero_si512();
    const std::size_t packed_before = out.size;
    __m256i position = _mm256_add_epi32(_mm256_set1_epi32(static_cast<int>(b)),
                                        _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    const __m256i eight = _mm256_set1_epi32(8);
    std::size_t n = out.size;
    for (std::size_t j = b; j < e; j += 8) {
        const __mmask8 valid =
            e - j >= 8 ? __mmask8{0xff} : static_cast<__mmask8>((1u << (e - j)) - 1);
        const __m512d dx = _mm512_sub_pd(x0, _mm512_maskz_loadu_pd(valid, x + j));
        const __m512d dy = _mm512_sub_pd(y0, _mm512_maskz_loadu_pd(valid, y + j));
        const __m512d d2 = _mm512_fmadd_pd(dy, dy, _mm512_mul_pd(dx, dx));
        __mmask8 in = _mm512_mask_cmp_pd_mask(valid, d2, r2, _CMP_LT_OQ);
        if constexpr (partners == Partners::fluid)
            in = _mm512_mask_cmp_pd_mask(in, _mm512_maskz_loadu_pd(valid, fluid + j), zero,
                                         _CMP_GT_OQ);
        if constexpr (count == Counted::remote) {
            const __mmask8 in_far = _mm512_mask_cmp_pd_mask(
                in, _mm512_maskz_loadu_pd(valid, far + j), zero, _CMP_GT_OQ);
            remote = _mm512_mask_add_epi64(remote, in_far, remote, one);
        }
        const __mmask8 keep = _mm512_mask_cmp_pd_mask(in, d2, zero, _CMP_GT_OQ);
        if constexpr (count != Counted::no)
            at_zero = _mm512_mask_add_epi64(at_zero, _kandn_mask8(keep, in), at_zero, one);
        _mm256_storeu_si256(reinterpret_cast<__m256i *>(index + n),
                            _mm256_maskz_compress_epi32(keep, position));
        // The separations as floats (PairReal). Not _mm512_cvtpd_ps: GCC 12 builds it on an
        // undefined register and warns (bug 105593), as lane_sum's note says.
        _mm256_storeu_ps(sx + n, _mm256_maskz_compress_ps(keep, _mm512_maskz_cvtpd_ps(keep, dx)));
        _mm256_storeu_ps(sy + n, _mm256_maskz_compress_ps(keep, _mm512_maskz_cvtpd_ps(keep, dy)));
        n += static_cast<std::size_t>(std::popcount(static_cast<unsigned>(keep)));
        position = _mm256_add_epi32(position, eight);
    }
    out.size = n;
    if constexpr (count != Counted::no)
        out.in_range += (n - packed_before) + lane_sum(at_zero);
    if constexpr (count == Counted::remote)
        out.remote += lane_sum(remote);
#elif defined(SPHPERF_AVX2_KERNELS)
    PackedCandidates *one[1] = {&out};
    const double xs[1] = {xi}, ys[1] = {yi};
    pack_range_avx2<count, partners, 1>(v, xs, ys, r2max, b, e, one);
#else
    pack_range_portable<count, partners>(v, xi, yi, r2max, b, e, out);
#endif
}

// Particles of one cell packed together (pack_range_avx2): a cell is a row of about four
// particles at the dam break's spacing.
constexpr int batch_size = pack_batch_size;

// Packs [b, e) for particles (xi[k], yi[k]), k < batch, into out[k].
template <Counted count, Partners partners>
void pack_ranges(const CellSorted::View &v, const double *xi, const double *yi, int batch,
                 double r2max, std::size_t b, std::size_t e, PackedCandidates *const *out) {
#if defined(SPHPERF_AVX2_KERNELS)
    static_assert(batch_size == 4);
    switch (batch) {
    case 1:
        return pack_range_avx2<count, partners, 1>(v, xi, yi, r2max, b, e, out);
    case 2:
        return pack_range_avx2<count, partners, 2>(v, xi, yi, r2max, b, e, out);
    case 3:
        return pack_range_avx2<count, partners, 3>(v, xi, yi, r2max, b, e, out);
    default:
        return pack_range_avx2<count, partners, 4>(v, xi, yi, r2max, b, e, out);
    }
#else
    for (int k = 0; k < batch; ++k)
        pack_range<count, partners>(v, xi[k], yi[k], r2max, b, e, *out[k]);
#endif
}

// Packs, for each particle self[k] (k < batch, all of cell (col, row)), the candidates of the
// 3 x 3 cells around the cell that interact with it into out[k] (see PackedCandidates), padded
// to whole vectors.
template <Counted count, Partners partners>
void pack_neighbourhoods(const CellSorted::View &v, int col, int row, const std::size_t *self,
                         int batch, double r2max, PackedCandidates *const *out) {
    constexpr int reach = CellSorted::rows_per_cell; // rows within 3h
    const int r0 = std::max(row - reach, 0), r1 = std::min(row + reach, v.rows - 1);
    const int c0 = std::max(col - 1, 0), c1 = std::min(col + 1, v.cols - 1);
    std::size_t candidates = 0;
    for (int c = c0; c <= c1; ++c)
        candidates += v.start[c * v.rows + r1 + 1] - v.start[c * v.rows + r0];
    double xi[batch_size], yi[batch_size];
    for (int k = 0; k < batch; ++k) {
        PackedCandidates &o = *out[k];
        // Room for every candidate, the vector stores past the last one and the padding.
        if (o.index.size() < candidates + pair_lanes) {
            const std::size_t room = std::bit_ceil(candidates + pair_lanes);
            o.index.resize(room);
            o.dx.resize(room);
            o.dy.resize(room);
        }
        o.size = 0;
        o.in_range = o.remote = 0;
        xi[k] = v.x[self[k]];
        yi[k] = v.y[self[k]];
    }
    for (int c = c0; c <= c1; ++c) {
        const std::size_t b = v.start[c * v.rows + r0], e = v.start[c * v.rows + r1 + 1];
        // A range without fluid holds no partner of a wall particle: a dry wall costs
        // nothing then (it examined about 100 candidates a step before; sph/NOTES.md).
        if (partners == Partners::fluid && v.fluid_in(c, r0, r1 + 1) == 0)
            continue;
        if (count == Counted::remote && !v.remote_columns[c])
            pack_ranges<Counted::in_range, partners>(v, xi, yi, batch, r2max, b, e, out);
        else
            pack_ranges<count, partners>(v, xi, yi, batch, r2max, b, e, out);
    }
    for (int k = 0; k < batch; ++k) {
        PackedCandidates &o = *out[k];
        o.padded = (o.size + pad_lanes - 1) / pad_lanes * pad_lanes;
        for (std::size_t q = o.size; q < o.padded; ++q) {
            o.index[q] = static_cast<std::uint32_t>(self[k]);
            o.dx[q] = o.dy[q] = 0;
        }
    }
}

template <Counted count, Partners partners>
void pack_neighbourhood(const CellSorted::View &v, int col, int row, std::size_t self, double r2max,
                        PackedCandidates &out) {
    PackedCandidates *const one[1] = {&out};
    pack_neighbourhoods<count, partners>(v, col, row, &self, 1, r2max, one);
}

} // namespace

void pack_in_range_portable(const CellSorted::View &v, double xi, double yi, double r2max,
                            bool fluid_only, std::size_t b, std::size_t e, PackedCandidates &out) {
    if (fluid_only)
        pack_range_portable<Counted::remote, Partners::fluid>(v, xi, yi, r2max, b, e, out);
    else
        pack_range_portable<Counted::remote, Partners::all>(v, xi, yi, r2max, b, e, out);
}

void pack_in_range(const CellSorted::View &v, double xi, double yi, double r2max, bool fluid_only,
                   std::size_t b, std::size_t e, PackedCandidates &out) {
    if (fluid_only)
        pack_range<Counted::remote, Partners::fluid>(v, xi, yi, r2max, b, e, out);
    else
        pack_range<Counted::remote, Partners::all>(v, xi, yi, r2max, b, e, out);
}

void pack_in_range(const CellSorted::View &v, const double *xi, const double *yi, int batch,
                   double r2max, bool fluid_only, std::size_t b, std::size_t e,
                   PackedCandidates *const *out) {
    if (batch < 1 || batch > batch_size)
        throw std::invalid_argument("pack_in_range: batch " + std::to_string(batch) +
                                    ", expected 1 to " + std::to_string(batch_size));
    if (fluid_only)
        pack_ranges<Counted::remote, Partners::fluid>(v, xi, yi, batch, r2max, b, e, out);
    else
        pack_ranges<Counted::remote, Partners::all>(v, xi, yi, batch, r2max, b, e, out);
}

namespace {

// The pair terms, written once for one lane (T = PairReal: the compiler vectorises the 16-lane
// loops) and for eight (T = Lanes8: the AVX2 loops), in the precision E = PairReal. Every lane
// computes finite terms, and a padding lane's is a signed zero with no mask: it pairs the
// particle with itself at separation 0, so its velocity difference, its kernel slope (at
// r = sqrt(tiny)) and its dx, dy are all exactly 0. A mask multiplied in cost three or four
// instructions per four pairs and kept the last product out of the sum's fused multiply-add.
// With `one_mass` the common mass is folded into the kernel's coefficients (w), else each term
// takes its neighbour's, mj.
[[gnu::always_inline]] inline float lane_sqrt(float x) {
    return std::sqrt(x);
}
[[gnu::always_inline]] inline double lane_sqrt(double x) {
    return std::sqrt(x);
}
template <class E> [[gnu::always_inline]] inline E lane_min0(E x) {
    return std::min(x, E{0});
}
#if defined(SPHPERF_AVX2_KERNELS)
[[gnu::always_inline]] inline Lanes8 lane_sqrt(Lanes8 x) {
    return _mm256_sqrt_ps(x);
}
[[gnu::always_inline]] inline Lanes8 lane_min0(Lanes8 x) {
    return _mm256_min_ps(x, _mm256_setzero_ps());
}
#endif

using PairSlope = BranchFreeKernel::ScaledSlopeOf<PairReal>;

// Continuity: m_j W'(r) / r (v_ij . r_ij), at the separation `back` earlier (physics.hpp
// continuity_term): neighbours by the end of the step, the rate at the step's middle.
template <bool one_mass, class T, class E>
[[gnu::always_inline]] inline T density_rate_term(const BranchFreeKernel::ScaledSlopeOf<E> &w,
                                                  E inv_h, E back, T dx, T dy, T dvx, T dvy, T mj) {
    const T mx = dx - back * dvx, my = dy - back * dvy;
    const T r = lane_sqrt(mx * mx + (my * my + tiny_of<E>)); // finite; tiny in a fused add
    // The division by r on v_ij . r_ij, which is ready early, not on the slope: it then runs
    // beside the slope's polynomial instead of after it.
    const T along = (dvx * mx + dvy * my) / r;
    T f = BranchFreeKernel::slope(r * inv_h, w);
    if constexpr (!one_mass)
        f = mj * f;
    return f * along;
}

// Particle i's side of the force pass.
template <class E> struct ForceParticle { E vx, vy, rho, p_over_rho2; };
template <class E> struct ForceConstants {
    E inv_h, eta2, visc_coef; // 1 / h; 0.01 h^2; -2 alpha c0 h
};
template <class T> struct Force { T x, y; };

// Pressure and Monaghan's viscosity: -m_j (P_i / rho_i^2 + P_j / rho_j^2 + Pi_ij) grad W.
template <bool one_mass, class T, class E>
[[gnu::always_inline]] inline Force<T>
force_term(const ForceConstants<E> &c, const BranchFreeKernel::ScaledSlopeOf<E> &w,
           const ForceParticle<E> &i, T dx, T dy, T vxj, T vyj, T rhoj, T prj, T mj) {
    // tiny in a fused add: d2 + eta2 below is the same as without it.
    const T d2 = dx * dx + (dy * dy + tiny_of<E>);
    const T r = lane_sqrt(d2);
    const T vdotr = (i.vx - vxj) * dx + (i.vy - vyj) * dy;
    // One division for three quotients, 1/r, 1/(r^2 + eta^2) and 1/(rho_i + rho_j): divisions
    // and the square root are what this loop waits on. Monaghan's viscosity is
    // visc_coef vdotr / dv, for approaching pairs only (vdotr < 0): clamping vdotr rather than
    // branching keeps the loop branch-free; receding pairs get 0. The bracket over r is then
    // (P_i / rho_i^2 + P_j / rho_j^2) dv + visc_coef min(vdotr, 0), over r dv: two
    // multiplications fewer than the viscosity and 1/r taken apart.
    const T dv = (d2 + c.eta2) * (i.rho + rhoj);
    const T inv = E{1} / (r * dv);
    T coef = ((i.p_over_rho2 + prj) * dv + c.visc_coef * lane_min0(vdotr)) * inv;
    if constexpr (!one_mass)
        coef = mj * coef;
    const T f = BranchFreeKernel::slope(r * c.inv_h, w) * coef;
    return {-f * dx, -f * dy};
}

#if defined(SPHPERF_AVX2_KERNELS)
static_assert(std::is_same_v<PairReal, float>, "the AVX2 pair loops are written for floats");

// PairSum::total() of the 16 lanes held as two groups of eight, in registers: the same tree
// (neighbouring lanes, then neighbouring pairs, ...), so the same bits. Through memory and
// scalar additions it took about 5 % of the run's samples (sph/NOTES.md, session 65).
[[gnu::always_inline]] inline float tree_sum(const Lanes8 (&g)[2]) {
    // Per 128-bit half [g0 01, g0 23, g1 01, g1 23 | g0 45, g0 67, g1 45, g1 67] (lane sums),
    // then [g0 0-3, g1 0-3, .. | g0 4-7, g1 4-7, ..], then the halves added, then g0 + g1.
    const __m256 a = _mm256_hadd_ps(g[0], g[1]);
    const __m256 b = _mm256_hadd_ps(a, a);
    const __m128 c = _mm_add_ps(_mm256_castps256_ps128(b), _mm256_extractf128_ps(b, 1));
    return _mm_cvtss_f32(_mm_add_ss(c, _mm_movehdup_ps(c)));
}

// Eight neighbours' vx, vy, rho and P / rho^2 from their records (View::records): eight
// 16-byte loads and a 4 x 4 transpose in each 128-bit half, where GCC's gathers take a load
// and a shuffle a lane.
struct Neighbours8 {
    Lanes8 vx, vy, rho, p_over_rho2;
};
[[gnu::always_inline]] inline Neighbours8 load_records(const float *records,
                                                       const std::uint32_t *j) {
    const auto two = [&](int lo, int hi) __attribute__((always_inline)) {
        return _mm256_insertf128_ps(
            _mm256_castps128_ps256(_mm_load_ps(records + 4 * std::size_t{j[lo]})),
            _mm_load_ps(records + 4 * std::size_t{j[hi]}), 1);
    };
    const __m256 r0 = two(0, 4), r1 = two(1, 5), r2 = two(2, 6), r3 = two(3, 7);
    const __m256 t0 = _mm256_unpacklo_ps(r0, r1), t1 = _mm256_unpackhi_ps(r0, r1),
                 t2 = _mm256_unpacklo_ps(r2, r3), t3 = _mm256_unpackhi_ps(r2, r3);
    return {_mm256_shuffle_ps(t0, t2, 0x44), _mm256_shuffle_ps(t0, t2, 0xee),
            _mm256_shuffle_ps(t1, t3, 0x44), _mm256_shuffle_ps(t1, t3, 0xee)};
}
[[gnu::always_inline]] inline Lanes8 gather8(const double *a, const std::uint32_t *j) {
    return _mm256_setr_ps(static_cast<float>(a[j[0]]), static_cast<float>(a[j[1]]),
                          static_cast<float>(a[j[2]]), static_cast<float>(a[j[3]]),
                          static_cast<float>(a[j[4]]), static_cast<float>(a[j[5]]),
                          static_cast<float>(a[j[6]]), static_cast<float>(a[j[7]]));
}

#endif

// A packed list where it lies: a pass's scratch (PackedCandidates) or sweep_forces' store.
struct PackView {
    const std::uint32_t *index;
    const PairReal *dx, *dy;
    std::size_t padded;
};
PackView view_of(const PackedCandidates &p) {
    return {p.index.data(), p.dx.data(), p.dy.data(), p.padded};
}

// The pair loops' constants in their precision, once per pass: the kernel's coefficients
// (alpha_d / h, times the mass where every particle has the same one, View::common_mass, which
// the loops then take as a constant) and 1 / h.
struct PairKernel {
    PairSlope w;
    PairReal inv_h;
};
PairKernel pair_kernel(const CellSorted::View &v, const BranchFreeKernel &k) {
    return {PairSlope(v.common_mass > 0 ? k.alpha_d_over_h * v.common_mass : k.alpha_d_over_h),
            static_cast<PairReal>(k.inv_h)};
}

// The sums of one particle over its packed candidates, lane l of the 16 taking positions
// q + l: the same lanes in either build, so the same sums to the rounding of the arithmetic.
// The AVX2 loops keep the sums in registers, two vectors of eight lanes.
// With `one_mass` every neighbour's mass is v.common_mass, folded into the kernel's
// coefficients (pair_kernel), not gathered.
template <bool one_mass>
[[gnu::always_inline]] inline double density_rate_sum(const CellSorted::View &v,
                                                      const PackView &nbr, const PairKernel &k,
                                                      PairReal back, PairReal vxi, PairReal vyi) {
    const std::uint32_t *idx = nbr.index;
    const PairReal *sx = nbr.dx, *sy = nbr.dy;
#if defined(SPHPERF_AVX2_KERNELS)
    constexpr int groups = pair_lanes / 8;
    Lanes8 sum[groups] = {};
    const Lanes8 vxi8 = _mm256_set1_ps(vxi), vyi8 = _mm256_set1_ps(vyi);
    const auto group = [&](std::size_t q, int g) __attribute__((always_inline)) {
        const std::uint32_t *j = idx + q + 8 * g;
        const Neighbours8 n = load_records(v.records, j);
        sum[g] += density_rate_term<one_mass>(
            k.w, k.inv_h, back, _mm256_load_ps(sx + q + 8 * g), _mm256_load_ps(sy + q + 8 * g),
            vxi8 - n.vx, vyi8 - n.vy, one_mass ? Lanes8{} : gather8(v.mass, j));
    };
    std::size_t q = 0;
    for (; q + pair_lanes <= nbr.padded; q += pair_lanes)
#pragma GCC unroll 2 // the groups interleaved: rolled, this lost to the compiler (session 63)
        for (int g = 0; g < groups; ++g)
            group(q, g);
    if (nbr.padded - q >= 8) // the last block's group of eight, if it holds one (padding to 8)
        group(q, 0);
    return tree_sum(sum);
#else
    PairSum drho;
    for (std::size_t q = 0; q < nbr.padded; q += pair_lanes) {
#pragma omp simd
        for (int l = 0; l < pair_lanes; ++l) {
            const std::uint32_t j = idx[q + l];
            drho.v[l] += density_rate_term<one_mass>(
                k.w, k.inv_h, back, sx[q + l], sy[q + l], vxi - static_cast<PairReal>(v.vx[j]),
                vyi - static_cast<PairReal>(v.vy[j]),
                one_mass ? PairReal{} : static_cast<PairReal>(v.mass[j]));
        }
    }
    return drho.total();
#endif
}

template <bool one_mass>
[[gnu::always_inline]] inline Force<double>
force_sum(const CellSorted::View &v, const PackView &nbr, const ForceConstants<PairReal> &c,
          const PairKernel &k, const ForceParticle<PairReal> &i) {
    const std::uint32_t *idx = nbr.index;
    const PairReal *sx = nbr.dx, *sy = nbr.dy;
#if defined(SPHPERF_AVX2_KERNELS)
    constexpr int groups = pair_lanes / 8;
    Lanes8 sum_x[groups] = {}, sum_y[groups] = {};
    const auto group = [&](std::size_t q, int g) __attribute__((always_inline)) {
        const std::uint32_t *j = idx + q + 8 * g;
        const Neighbours8 n = load_records(v.records, j);
        const Force<Lanes8> a = force_term<one_mass>(
            c, k.w, i, _mm256_load_ps(sx + q + 8 * g), _mm256_load_ps(sy + q + 8 * g), n.vx, n.vy,
            n.rho, n.p_over_rho2, one_mass ? Lanes8{} : gather8(v.mass, j));
        sum_x[g] += a.x;
        sum_y[g] += a.y;
    };
    std::size_t q = 0;
    for (; q + pair_lanes <= nbr.padded; q += pair_lanes)
#pragma GCC unroll 2 // the groups interleaved: rolled, this lost to the compiler (session 63)
        for (int g = 0; g < groups; ++g)
            group(q, g);
    if (nbr.padded - q >= 8) // the last block's group of eight, if it holds one (padding to 8)
        group(q, 0);
    return {tree_sum(sum_x), tree_sum(sum_y)};
#else
    PairSum ax, ay;
    const auto real = [](double x) { return static_cast<PairReal>(x); };
    for (std::size_t q = 0; q < nbr.padded; q += pair_lanes) {
#pragma omp simd
        for (int l = 0; l < pair_lanes; ++l) {
            const std::uint32_t j = idx[q + l];
            const Force<PairReal> a = force_term<one_mass>(
                c, k.w, i, sx[q + l], sy[q + l], real(v.vx[j]), real(v.vy[j]), real(v.rho[j]),
                real(v.p_over_rho2[j]), one_mass ? PairReal{} : real(v.mass[j]));
            ax.v[l] += a.x;
            ay.v[l] += a.y;
        }
    }
    return {ax.total(), ay.total()};
#endif
}

// density_rate_sum with the mass taken as a constant where every particle has the same one.
[[gnu::always_inline]] inline double density_rate(const CellSorted::View &v, const PackView &nbr,
                                                  const PairKernel &k, PairReal back, double vxi,
                                                  double vyi) {
    const auto x = static_cast<PairReal>(vxi), y = static_cast<PairReal>(vyi);
    return v.common_mass > 0 ? density_rate_sum<true>(v, nbr, k, back, x, y)
                             : density_rate_sum<false>(v, nbr, k, back, x, y);
}

// A thread's packs for the owned fluid particles of one cell, taken up to batch_size at a time
// (pack_neighbourhoods: they share the cell's candidate ranges).
struct CellBatch {
    PackedCandidates pack[batch_size];
    PackedCandidates *const out[batch_size] = {&pack[0], &pack[1], &pack[2], &pack[3]};
    std::size_t self[batch_size] = {};
    CellBatch() = default;
    CellBatch(const CellBatch &) = delete;
    CellBatch &operator=(const CellBatch &) = delete;
    // Takes the next owned particles of sorted positions [s, e) that are fluid (or, with
    // `fluid` false, walls) into self, up to batch_size of them; returns how many it took
    // (0: [s, e) holds no more).
    int next(const CellSorted::View &v, std::size_t &s, std::size_t e, bool fluid) {
        int n = 0;
        for (; s < e && n < batch_size; ++s)
            if (v.orig[s] < v.owned && (v.fluid[s] > 0) == fluid)
                self[n++] = s;
        return n;
    }
};

// This thread's cells of the view (inside a parallel region).
std::pair<int, int> thread_cells(const CellSorted::View &v) {
    const auto [c0, c1] =
        thread_cells(v.blocks, v.threads, static_cast<std::size_t>(v.cols) * v.rows);
    return {static_cast<int>(c0), static_cast<int>(c1)};
}

// A pair pass's cells for the calling thread (inside the parallel region; grid.start_pass()
// before it): chunks of its own block, then of the others' (CellSorted::next_cells), or with
// another team size than the blocks' one equal share, not booked. Books the thread's time and
// the cost of its cells in `columns` to the grid when it goes out of scope; the next step's
// blocks are cut by them. The passes keep their cell loops as they were: a lambda per cell
// made GCC call the force pass's per-particle body instead of inlining it, and the density
// pass ran 9 % slower at 1 thread (session 62).
class ThreadCells {
public:
    ThreadCells(CellSorted &grid, const CellSorted::View &v, ColumnSet columns)
        : grid_(grid), v_(v), columns_(columns), thread_(omp_get_thread_num()),
          chunked_(omp_get_num_threads() == v.threads), start_(omp_get_wtime()) {}
    ThreadCells(const ThreadCells &) = delete;
    ThreadCells &operator=(const ThreadCells &) = delete;
    ~ThreadCells() { grid_.add_pass_time(thread_, omp_get_wtime() - start_, cost_); }
    // The next range of cells, [first, last); false when none is left.
    bool next(int &first, int &last) {
        std::uint32_t c0 = 0, c1 = 0;
        if (chunked_) {
            if (!grid_.next_cells(thread_, c0, c1))
                return false;
        } else {
            if (share_taken_)
                return false;
            share_taken_ = true;
            const auto [a, b] = thread_cells(v_);
            c0 = static_cast<std::uint32_t>(a);
            c1 = static_cast<std::uint32_t>(b);
        }
        for (std::uint32_t c = c0; c < c1; ++c)
            if (columns_.contains(static_cast<int>(c) / v_.rows))
                cost_ += v_.cost[c + 1] - v_.cost[c];
        first = static_cast<int>(c0);
        last = static_cast<int>(c1);
        return true;
    }

private:
    CellSorted &grid_;
    const CellSorted::View &v_;
    ColumnSet columns_;
    int thread_;
    bool chunked_, share_taken_ = false;
    double start_;
    std::uint64_t cost_ = 0;
};

// Runs per_particle(sorted index, col, row, scratch) for every owned particle of the columns,
// each thread over its block of cells (balanced by the grid: the water is not spread evenly)
// with its own scratch.
template <class F>
void for_each_owned(CellSorted &grid, const CellSorted::View &v, ColumnSet columns,
                    F &&per_particle) {
    grid.start_pass();
#pragma omp parallel
    {
        PackedCandidates scratch;
        ThreadCells cells(grid, v, columns);
        for (int c0 = 0, c1 = 0; cells.next(c0, c1);)
            for (int cell = c0; cell < c1; ++cell) {
                const int col = cell / v.rows, row = cell % v.rows;
                if (!columns.contains(col))
                    continue;
                for (std::size_t s = v.start[cell]; s < v.start[cell + 1]; ++s)
                    if (v.orig[s] < v.owned)
                        per_particle(s, col, row, scratch);
            }
    }
}

// The pair passes' constants, once per pass.
struct PassConstants {
    PairKernel k;
    ForceConstants<PairReal> force;
    PairReal back; // the density pass's separations this much earlier (continuity_term)
    double r2max, gravity;
};
PassConstants pass_constants(const CellSorted::View &v, const Physics &phys, double back) {
    const BranchFreeKernel kernel(phys.kernel());
    const auto real = [](double x) { return static_cast<PairReal>(x); };
    return {pair_kernel(v, kernel),
            {real(kernel.inv_h), real(0.01 * kernel.h * kernel.h),
             real(-2 * phys.alpha * phys.c0 * kernel.h)},
            real(back),
            phys.cell_size() * phys.cell_size(),
            phys.gravity};
}

// The density pass over one cell's owned particles, counting the interactions and their
// remote share; kept(i, pack) sees each fluid particle's pack after its rate. A fluid particle
// interacts with every particle within 3h, itself included in the count (subtracted here; its
// own term is 0); a wall particle with fluid particles only, so not with itself.
template <class Kept>
[[gnu::always_inline]] inline void
density_cell(Particles &p, const CellSorted::View &v, const PassConstants &pc, int cell,
             CellBatch &batch, std::uint64_t &interactions, std::uint64_t &remote, Kept &&kept) {
    const int col = cell / v.rows, row = cell % v.rows;
    for (const bool fluid : {true, false})
        for (std::size_t s = v.start[cell];
             const int n = batch.next(v, s, v.start[cell + 1], fluid);) {
            if (fluid)
                pack_neighbourhoods<Counted::remote, Partners::all>(v, col, row, batch.self, n,
                                                                    pc.r2max, batch.out);
            else
                pack_neighbourhoods<Counted::remote, Partners::fluid>(v, col, row, batch.self, n,
                                                                      pc.r2max, batch.out);
            for (int b = 0; b < n; ++b) {
                const std::size_t i = batch.self[b];
                const PackedCandidates &pack = batch.pack[b];
                const std::uint32_t o = v.orig[i];
                p.drho[o] = density_rate(v, view_of(pack), pc.k, pc.back, p.vx[o], p.vy[o]);
                interactions += pack.in_range - (fluid ? 1 : 0);
                remote += pack.remote;
                if (fluid)
                    kept(i, pack);
            }
        }
}

// Fluid particle i's acceleration from its packed neighbours.
[[gnu::always_inline]] inline void force_on(Particles &p, const CellSorted::View &v,
                                            const PassConstants &pc, std::size_t i,
                                            const PackView &pack) {
    const auto real = [](double x) { return static_cast<PairReal>(x); };
    const std::uint32_t o = v.orig[i];
    // Its own density and P / rho^2 as refresh_density left them for its neighbours: with the
    // records their values (the doubles are not kept then), else the doubles.
    PairReal rho, p_over_rho2;
    if constexpr (pair_records) {
        rho = v.records[4 * i + 2];
        p_over_rho2 = v.records[4 * i + 3];
    } else {
        rho = real(v.rho[i]);
        p_over_rho2 = real(v.p_over_rho2[i]);
    }
    const ForceParticle<PairReal> fi{real(p.vx[o]), real(p.vy[o]), rho, p_over_rho2};
    const Force<double> a = v.common_mass > 0 ? force_sum<true>(v, pack, pc.force, pc.k, fi)
                                              : force_sum<false>(v, pack, pc.force, pc.k, fi);
    p.ax[o] = a.x;
    p.ay[o] = a.y - pc.gravity;
}

// Wall particles do not move.
void still_walls(Particles &p, const CellSorted::View &v, int cell) {
    for (std::size_t i = v.start[cell]; i < v.start[cell + 1]; ++i)
        if (v.orig[i] < v.owned && v.fluid[i] == 0) {
            p.ax[v.orig[i]] = 0;
            p.ay[v.orig[i]] = 0;
        }
}

// The force pass over one cell: its walls stay still, its fluid particles' neighbours are
// packed (a batch at a time) and summed.
[[gnu::always_inline]] inline void force_cell(Particles &p, const CellSorted::View &v,
                                              const PassConstants &pc, int cell, CellBatch &batch) {
    const int col = cell / v.rows, row = cell % v.rows;
    still_walls(p, v, cell);
    // Fluid particles: every j interacts.
    for (std::size_t s = v.start[cell]; const int n = batch.next(v, s, v.start[cell + 1], true);) {
        pack_neighbourhoods<Counted::no, Partners::all>(v, col, row, batch.self, n, pc.r2max,
                                                        batch.out);
        for (int b = 0; b < n; ++b)
            force_on(p, v, pc, batch.self[b], view_of(batch.pack[b]));
    }
}
} // namespace

void continuity(Particles &p, SortedNeighbours &nb, const Physics &phys, double back) {
    nb.counts = continuity_columns(p, nb, phys, back, ColumnSet{}).counts();
}

DensityCounts continuity_columns(Particles &p, SortedNeighbours &nb, const Physics &phys,
                                 double back, ColumnSet columns) {
    const CellSorted::View v = nb.grid->view();
    const PassConstants pc = pass_constants(v, phys, back);
    std::uint64_t interactions = 0, remote = 0;
    nb.grid->start_pass();
#pragma omp parallel reduction(+ : interactions, remote)
    {
        CellBatch batch;
        ThreadCells cells(*nb.grid, v, columns);
        for (int c0 = 0, c1 = 0; cells.next(c0, c1);)
            for (int cell = c0; cell < c1; ++cell)
                if (columns.contains(cell / v.rows))
                    density_cell(p, v, pc, cell, batch, interactions, remote,
                                 [](std::size_t, const PackedCandidates &) {});
    }
    return {interactions, remote};
}

void momentum(Particles &p, SortedNeighbours &nb, const Physics &phys) {
    nb.grid->refresh_density(p);
    momentum_columns(p, nb, phys, ColumnSet{});
}

void momentum_columns(Particles &p, SortedNeighbours &nb, const Physics &phys, ColumnSet columns) {
    const CellSorted::View v = nb.grid->view();
    const PassConstants pc = pass_constants(v, phys, 0);
    nb.grid->start_pass();
#pragma omp parallel
    {
        CellBatch batch;
        ThreadCells cells(*nb.grid, v, columns);
        for (int c0 = 0, c1 = 0; cells.next(c0, c1);)
            for (int cell = c0; cell < c1; ++cell) {
                if (columns.contains(cell / v.rows))
                    force_cell(p, v, pc, cell, batch);
            }
    }
}

namespace {
// Density advance, equation of state and sorted-copy refresh of the owned particles at sorted
// positions [from, to) (integrator.hpp advance_density, physics.hpp equation_of_state).
void advance_positions(Particles &p, CellSorted &grid, const CellSorted::View &v,
                       const Physics &phys, double dt, std::size_t from, std::size_t to) {
    for (std::size_t s = from; s < to; ++s)
        if (const std::uint32_t i = v.orig[s]; i < v.owned) {
            p.rho[i] += dt * p.drho[i];
            p.p[i] = phys.pressure(p.rho[i]);
        }
    grid.refresh_density(p, from, to);
}
} // namespace

void advance_columns(Particles &p, SortedNeighbours &nb, const Physics &phys, double dt,
                     ColumnSet columns) {
    const CellSorted::View v = nb.grid->view();
    const auto rows = static_cast<std::size_t>(v.rows);
    for (int col = 0; col < v.cols; ++col)
        if (columns.contains(col))
            advance_positions(p, *nb.grid, v, phys, dt, v.start[col * rows],
                              v.start[(col + 1) * rows]);
}

void sweep_forces(Particles &p, SortedNeighbours &nb, const Physics &phys, double back, double dt,
                  const std::function<void()> &ghost_densities) {
    nb.counts = sweep_columns(p, nb, phys, back, dt, ColumnSet{}).counts();
    if (ghost_densities)
        ghost_densities();
    force_held_columns(p, nb, phys);
}

DensityCounts sweep_columns(Particles &p, SortedNeighbours &nb, const Physics &phys, double back,
                            double dt, ColumnSet columns) {
    if (columns.outside)
        throw std::logic_error("sweep_columns: the columns must be one range");
    CellSorted &grid = *nb.grid;
    const CellSorted::View v = grid.view();
    const PassConstants pc = pass_constants(v, phys, back);
    CellSorted::Sweep &sw = grid.sweep();
    const std::size_t sorted = v.start[static_cast<std::size_t>(v.cols) * v.rows];
    sw.offset.resize(sorted);
    sw.length.resize(sorted);
    if (sw.columns < v.cols) {
        sw.column_done = std::make_unique<std::atomic<int>[]>(static_cast<std::size_t>(v.cols));
        sw.columns = v.cols;
    }
    for (int col = 0; col < v.cols; ++col)
        sw.column_done[col].store(0, std::memory_order_relaxed);
    const auto rows = static_cast<std::size_t>(v.rows);
    const int first = std::max(columns.first, 0), last = std::min(columns.last, v.cols - 1);
    // Its forces wait: a neighbour holds ghosts, or the column itself, or lies out of the sweep.
    const auto held = [&](int col) {
        const auto remote = [&](int c) {
            return c >= 0 && c < v.cols && (v.remote_columns[c] != 0 || c < first || c > last);
        };
        return remote(col - 1) || remote(col) || remote(col + 1);
    };
    grid.start_sweep();
    std::uint64_t interactions = 0, remote = 0;
#pragma omp parallel reduction(+ : interactions, remote)
    {
        const int t = omp_get_thread_num(), threads = omp_get_num_threads();
        const double start = omp_get_wtime();
        double waited = 0;
        std::uint64_t cost = 0;
#pragma omp single
        sw.threads.resize(static_cast<std::size_t>(threads));
        CellSorted::SweepThread &mine = sw.threads[static_cast<std::size_t>(t)];
        mine.waiting.clear();
        mine.held.clear();
        // Columns in chunks (CellSorted::next_columns), or with another team size than the
        // blocks were cut for, an equal share each.
        const bool chunked = threads == v.threads;
        bool share_taken = false;
        const auto next = [&](int &from, int &to) {
            std::uint32_t c0 = 0, c1 = 0;
            if (chunked) {
                if (!grid.next_columns(t, c0, c1))
                    return false;
            } else {
                if (share_taken)
                    return false;
                share_taken = true;
                c0 = static_cast<std::uint32_t>(static_cast<long>(v.cols) * t / threads);
                c1 = static_cast<std::uint32_t>(static_cast<long>(v.cols) * (t + 1) / threads);
            }
            // Clipped to the swept columns (an empty chunk is skipped).
            from = std::clamp(static_cast<int>(c0), first, last + 1);
            to = std::clamp(static_cast<int>(c1), first, last + 1);
            cost += v.cost[to * rows] - v.cost[from * rows];
            return true;
        };
        // Columns taken in a row form a run: the force pass of each follows the density pass
        // of the next, reading the packs where the density pass left them, stores 0 and 1 in
        // turn. The thread's first column keeps its packs in store 2: its west neighbour is
        // most often the last column of the thread before, done at the end.
        int run_first = -1, run_last = -1, kept = -1;
        const auto store_of = [&](int col) -> CellSorted::SweepStore & {
            return mine.stores[col == kept ? 2 : static_cast<std::size_t>(col % 2)];
        };
        const auto done = [&](int col) {
            return col < 0 || col >= v.cols ||
                   sw.column_done[col].load(std::memory_order_acquire) != 0;
        };
        const auto force_stored = [&](int col) {
            const CellSorted::SweepStore &st = store_of(col);
            for (int cell = col * v.rows; cell < (col + 1) * v.rows; ++cell) {
                still_walls(p, v, cell);
                for (std::size_t i = v.start[cell]; i < v.start[cell + 1]; ++i)
                    if (v.orig[i] < v.owned && v.fluid[i] > 0)
                        force_on(p, v, pc, i,
                                 {st.index.data() + sw.offset[i], st.dx.data() + sw.offset[i],
                                  st.dy.data() + sw.offset[i], sw.length[i]});
            }
        };
        // A column whose neighbours are not both done waits for the end, one beside ghosts
        // for their densities (their packs are overwritten by then, except the kept column's).
        const auto settle = [&](int col, bool neighbours_done) {
            if (held(col))
                mine.held.push_back(col);
            else if (neighbours_done || (done(col - 1) && done(col + 1)))
                force_stored(col);
            else
                mine.waiting.push_back(col);
        };
        const auto close_run = [&] {
            if (run_first >= 0)
                settle(run_last, false); // the first one too when the run has one column
        };
        CellBatch batch;
        for (int c0 = 0, c1 = 0; next(c0, c1);) {
            if (c0 == c1)
                continue;
            if (run_first < 0 || c0 != run_last + 1) {
                close_run();
                if (run_first < 0)
                    kept = c0;
                run_first = c0;
            }
            for (int col = c0; col < c1; ++col) {
                CellSorted::SweepStore &st = store_of(col);
                st.used = 0;
                for (int cell = col * v.rows; cell < (col + 1) * v.rows; ++cell)
                    density_cell(p, v, pc, cell, batch, interactions, remote,
                                 [&](std::size_t i, const PackedCandidates &pack) {
                                     const std::size_t n = pack.padded, need = st.used + n;
                                     if (st.index.size() < need) {
                                         const std::size_t room = std::bit_ceil(need);
                                         st.index.resize(room);
                                         st.dx.resize(room);
                                         st.dy.resize(room);
                                     }
                                     std::copy_n(pack.index.data(), n, st.index.data() + st.used);
                                     std::copy_n(pack.dx.data(), n, st.dx.data() + st.used);
                                     std::copy_n(pack.dy.data(), n, st.dy.data() + st.used);
                                     sw.offset[i] = static_cast<std::uint32_t>(st.used);
                                     sw.length[i] = static_cast<std::uint32_t>(n);
                                     st.used = need;
                                 });
                advance_positions(p, grid, v, phys, dt, v.start[col * rows],
                                  v.start[(col + 1) * rows]);
                sw.column_done[col].store(1, std::memory_order_release);
                run_last = col;
                if (col - 1 >= run_first)
                    settle(col - 1, col - 1 > run_first); // then both neighbours are this run's
            }
        }
        close_run();
        // Every column's density pass is taken by now, so each wait ends.
        for (const int col : mine.waiting) {
            const double from = omp_get_wtime();
            while (!done(col - 1) || !done(col + 1)) {
            }
            waited += omp_get_wtime() - from;
            if (col == kept)
                force_stored(col);
            else
                for (int cell = col * v.rows; cell < (col + 1) * v.rows; ++cell)
                    force_cell(p, v, pc, cell, batch);
        }
        if (chunked)
            grid.add_pass_time(t, omp_get_wtime() - start - waited, cost);
    }
    return {interactions, remote};
}

void force_held_columns(Particles &p, SortedNeighbours &nb, const Physics &phys) {
    const CellSorted::Sweep &sw = nb.grid->sweep();
    bool any_held = false;
    for (const CellSorted::SweepThread &u : sw.threads)
        any_held = any_held || !u.held.empty();
    if (!any_held)
        return;
    const CellSorted::View v = nb.grid->view();
    const PassConstants pc = pass_constants(v, phys, 0);
#pragma omp parallel
    {
        CellBatch batch;
        const auto n = static_cast<std::size_t>(omp_get_num_threads());
        for (auto u = static_cast<std::size_t>(omp_get_thread_num()); u < sw.threads.size(); u += n)
            for (const int col : sw.threads[u].held)
                for (int cell = col * v.rows; cell < (col + 1) * v.rows; ++cell)
                    force_cell(p, v, pc, cell, batch);
    }
}

void shepard_filter(Particles &p, SortedNeighbours &nb, const Physics &phys) {
    nb.grid->refresh_filter_fields(p);
    const CellSorted::View v = nb.grid->view();
    const BranchFreeKernel k(phys.kernel());
    const double r2max = phys.cell_size() * phys.cell_size();
    const double w0 = k.value(0.0);
    std::vector<double> filtered(p.owned(), 0.0);
    for_each_owned(*nb.grid, v, ColumnSet{},
                   [&](std::size_t i, int col, int row, PackedCandidates &) {
                       if (v.fluid[i] == 0)
                           return; // wall densities follow the continuity equation
                       const double xi = v.x[i], yi = v.y[i];
                       LaneSum num, den;
                       for_each_candidate(v, col, row, [&](std::size_t j, int l) {
                           const double dx = xi - v.x[j], dy = yi - v.y[j];
                           const double d2 = dx * dx + dy * dy;
                           const bool in = (d2 < r2max) & (j != i);
                           const double wr = k.value(std::sqrt(d2)); // 0 beyond the support anyway
                           const double w = in ? wr : 0.0;
                           num.v[l] += v.mass[j] * w;
                           den.v[l] += v.mass[j] / v.rho[j] * w;
                       });
                       filtered[v.orig[i]] = (v.mass[i] * w0 + num.total()) /
                                             (v.mass[i] / v.rho[i] * w0 + den.total());
                   });
    for (std::size_t i = 0; i < p.fluid(); ++i)
        p.rho[i] = filtered[i];
}

} // namespace sphperf::sph
