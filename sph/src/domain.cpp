#include "sphperf/sph/domain.hpp"

#include "sphperf/timer.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <exception>
#include <numeric>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>

namespace sphperf::sph {

namespace {
constexpr int tag_migrate = 11;
constexpr int tag_ghost = 12;
constexpr int tag_density = 13;
constexpr int tag_probe = 14;
static_assert(std::is_trivially_copyable_v<ParticleRecord>);
} // namespace

// Ghosts and their densities through an MPI-3 shared-memory window (sph --halo-transport
// window). On one node two-sided messages copy each payload twice, into shared buffers and
// out (or once by the receiver, above the eager limit), on the ranks' own cores: that copying
// was most of what an overlapped exchange left exposed (sph/NOTES.md, "Overlap"). Here every
// rank owns one segment: per direction (0: toward the west neighbour, 1: toward the east) the
// sequence number of its last post and the payloads' bytes on one line, and two payload buffers
// per direction used by turns, so it packs the next payload while its neighbour may still land
// the last. A sender packs straight into its segment, a receiver lands straight from its
// neighbour's. Order comes from release stores and acquire loads of the sequence words (the
// window's memory model is checked unified).
class HaloWindow {
public:
    struct Payload {
        const std::byte *data = nullptr;
        std::size_t bytes = 0;
    };

    HaloWindow(MPI_Comm comm, int west, int east, std::size_t capacity)
        : capacity_((capacity + line - 1) / line * line) {
        MPI_Comm node;
        MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
        int here = 0, all = 0;
        MPI_Comm_size(node, &here);
        MPI_Comm_size(comm, &all);
        if (here != all) {
            MPI_Comm_free(&node);
            throw std::runtime_error("--halo-transport window: " + std::to_string(here) +
                                     " of the job's " + std::to_string(all) +
                                     " ranks share this node; expected all of them");
        }
        // Ranks keep their order (key 0), so a neighbour's rank is the same in `node`.
        void *base = nullptr;
        MPI_Win_allocate_shared(static_cast<MPI_Aint>(header + 4 * capacity_), 1, MPI_INFO_NULL,
                                node, &base, &win_);
        MPI_Comm_free(&node);
        int *memory_model = nullptr, flag = 0;
        MPI_Win_get_attr(win_, MPI_WIN_MODEL, &memory_model, &flag);
        if (!flag || *memory_model != MPI_WIN_UNIFIED) {
            MPI_Win_free(&win_);
            throw std::runtime_error("--halo-transport window: this MPI's shared windows are "
                                     "not in the unified memory model");
        }
        mine_ = static_cast<std::byte *>(base);
        std::fill_n(mine_, header, std::byte{0});
        peer_[0] = segment(west);
        peer_[1] = segment(east);
        MPI_Win_lock_all(MPI_MODE_NOCHECK, win_);
        MPI_Barrier(comm); // every header zeroed before anyone looks at it
    }
    ~HaloWindow() {
        // Freeing is collective: a rank unwinding from an error would wait here for neighbours
        // that spin on its sequence words, and never reach the MPI_Abort that ends the job.
        if (std::uncaught_exceptions() > 0)
            return;
        MPI_Win_unlock_all(win_);
        MPI_Win_free(&win_);
    }
    HaloWindow(const HaloWindow &) = delete;
    HaloWindow &operator=(const HaloWindow &) = delete;

    std::size_t capacity() const { return capacity_; }
    // This rank's buffer toward `dir` for the next post; nullptr without a neighbour there. No
    // word says a neighbour has landed a payload: each rank takes in every post of its
    // neighbours before it posts again, and lands what it took before that. The buffer this
    // rank now fills held its post of two before; the neighbour landed that before it posted
    // the one this rank last took in (an acquire of that post's sequence word), so the landing
    // happened before this reuse.
    std::byte *outgoing(int dir) {
        if (awaiting_)
            throw std::logic_error("--halo-transport window: a post before the last was taken in");
        return peer_[dir] ? buffer(mine_, dir, seq_ + 1) : nullptr;
    }
    // Posts what outgoing() buffers now hold (bytes toward the west and east).
    void publish(std::size_t west_bytes, std::size_t east_bytes) {
        if (awaiting_)
            throw std::logic_error("--halo-transport window: a post before the last was taken in");
        const std::uint64_t next = ++seq_;
        awaiting_ = true;
        const std::array<std::size_t, 2> bytes{west_bytes, east_bytes};
        for (int dir : {0, 1}) {
            if (!peer_[dir])
                continue;
            if (bytes[dir] > capacity_)
                throw std::logic_error("--halo-transport window: a payload above the segment");
            *size_word(mine_, dir, next) = bytes[dir];
            std::atomic_ref<std::uint64_t>(*word(mine_, posted_line + dir))
                .store(next, std::memory_order_release);
        }
    }
    // The neighbours' payloads of the current post (from the west, from the east), once both
    // posted it; they stay there until this rank posts again (a neighbour refills that buffer
    // only after taking in this rank's next post).
    std::pair<Payload, Payload> incoming() {
        auto from = [&](int side) -> Payload {
            std::byte *peer = peer_[side];
            if (!peer)
                return {};
            const int dir = 1 - side; // the west neighbour sent it east
            spin_until(word(peer, posted_line + dir), seq_);
            return {buffer(peer, dir, seq_), *size_word(peer, dir, seq_)};
        };
        awaiting_ = false;
        return {from(0), from(1)};
    }

private:
    static constexpr std::size_t line = 64;
    // A post's sizes share its sequence word's line: a neighbour reads one line per post.
    static constexpr std::size_t posted_line = 0;
    static constexpr std::size_t header = 2 * line;
    static std::uint64_t *word(std::byte *seg, std::size_t l) {
        return reinterpret_cast<std::uint64_t *>(seg + l * line);
    }
    static std::size_t *size_word(std::byte *seg, int dir, std::uint64_t seq) {
        return reinterpret_cast<std::size_t *>(seg + (posted_line + dir) * line) + 1 + (seq & 1);
    }
    std::byte *buffer(std::byte *seg, int dir, std::uint64_t seq) const {
        return seg + header + (2 * static_cast<std::size_t>(dir) + (seq & 1)) * capacity_;
    }
    // Spins, then yields (ranks above the cores take turns), until *w >= at_least.
    static void spin_until(std::uint64_t *w, std::uint64_t at_least) {
        std::atomic_ref<std::uint64_t> a(*w);
        for (int i = 0; a.load(std::memory_order_acquire) < at_least; ++i)
            if (i >= spins_before_yield)
                std::this_thread::yield();
    }
    static constexpr int spins_before_yield = 2000;
    std::byte *segment(int peer) const {
        if (peer == MPI_PROC_NULL)
            return nullptr;
        MPI_Aint size = 0;
        int disp = 0;
        void *p = nullptr;
        MPI_Win_shared_query(win_, peer, &size, &disp, &p);
        return static_cast<std::byte *>(p);
    }
    std::size_t capacity_;
    MPI_Win win_ = MPI_WIN_NULL;
    std::byte *mine_ = nullptr;
    std::array<std::byte *, 2> peer_{};
    std::uint64_t seq_ = 0; // posts so far; every rank posts the same exchanges in turn
    bool awaiting_ = false; // posted, the neighbours' posts not yet taken in
};

int Slab::owner_of_column(int column) const {
    const int c = std::clamp(column, 0, columns - 1);
    // The last rank whose first column is <= c.
    return static_cast<int>(std::upper_bound(cuts.begin() + 1, cuts.end() - 1, c) -
                            (cuts.begin() + 1));
}

int Slab::owner_of(double x) const {
    return owner_of_column(static_cast<int>(std::floor(x / cell_size)));
}

Domain::Domain(MPI_Comm comm, int columns, double cell_size) : comm_(comm) {
    MPI_Comm_rank(comm, &slab_.rank);
    MPI_Comm_size(comm, &slab_.ranks);
    slab_.columns = columns;
    slab_.cell_size = cell_size;
    slab_.cuts = equal_cuts(slab_.ranks, columns);
    slab_.begin = slab_.cuts[static_cast<std::size_t>(slab_.rank)];
    slab_.end = slab_.cuts[static_cast<std::size_t>(slab_.rank) + 1];
    if (slab_.rank > 0)
        west_ = slab_.rank - 1;
    if (slab_.rank + 1 < slab_.ranks)
        east_ = slab_.rank + 1;
}

Domain::~Domain() = default;

void Domain::open_window(const Particles &p) {
    if (!window_wanted_ || window_)
        return;
    const auto held = static_cast<std::size_t>(sum(static_cast<long long>(p.size())));
    window_ = std::make_unique<HaloWindow>(comm_, west_, east_, 2 * held * sizeof(ParticleRecord));
}

CellWindow Domain::window(int cell_rows) const {
    return slab_window(slab_.cell_size, slab_.begin, slab_.end, cell_rows);
}

namespace {
// A phase scope that times nothing when no timers are attached.
class MaybePhase {
public:
    MaybePhase(PhaseTimers *t, Phase p) {
        if (t)
            scope_.emplace(*t, p);
    }

private:
    std::optional<ScopedPhase> scope_;
};
} // namespace

std::size_t Domain::shift_index(int tag) {
    switch (tag) {
    case tag_migrate:
        return static_cast<std::size_t>(Shift::migration);
    case tag_ghost:
        return static_cast<std::size_t>(Shift::ghosts);
    case tag_density:
        return static_cast<std::size_t>(Shift::densities);
    default:
        throw std::logic_error("Domain: an exchange with an unknown tag");
    }
}

std::pair<double, double> Domain::gaps(int tag, double now) {
    const double kind = last_end(tag);
    return {last_any_end_s_ > 0 ? now - last_any_end_s_ : 0.0, kind > 0 ? now - kind : 0.0};
}

void Domain::shift_ended(int tag, double when) {
    last_any_end_s_ = last_end(tag) = when;
}

double Domain::probe_latency() {
    if (!probe_ || slab_.ranks == 1)
        return 0;
    // The first rounds after an interval's compute are cold: the benchmark's figure is the
    // mean of a long back-to-back run after a warm-up.
    constexpr int warmup = 64, rounds = 64;
    constexpr int payload_bytes = 64;
    std::array<char, payload_bytes> out{}, in{};
    double spent = 0;
    for (int i = -warmup; i < rounds; ++i) {
        // As the benchmark: the handshake first (untimed), then count and payload each way.
        handshake(tag_probe);
        const double t0 = wall_seconds();
        for (const auto &[dest, src] : {std::pair{east_, west_}, std::pair{west_, east_}}) {
            int n_out = payload_bytes, n_in = 0;
            MPI_Sendrecv(&n_out, 1, MPI_INT, dest, tag_probe, &n_in, 1, MPI_INT, src, tag_probe,
                         comm_, MPI_STATUS_IGNORE);
            MPI_Sendrecv(out.data(), dest == MPI_PROC_NULL ? 0 : payload_bytes, MPI_BYTE, dest,
                         tag_probe, in.data(), src == MPI_PROC_NULL ? 0 : payload_bytes, MPI_BYTE,
                         src, tag_probe, comm_, MPI_STATUS_IGNORE);
        }
        if (i >= 0)
            spent += wall_seconds() - t0;
    }
    return spent / rounds;
}

void Domain::wait_for_neighbours(int tag) {
    // A zero-byte handshake each way: it returns once both neighbours have arrived, so the time
    // spent here is the wait for the slower one, and the transfers after it are timed alone.
    MaybePhase t(timers_, Phase::wait);
    handshake(tag);
}

void Domain::handshake(int tag) const {
    MPI_Sendrecv(nullptr, 0, MPI_BYTE, east_, tag, nullptr, 0, MPI_BYTE, west_, tag, comm_,
                 MPI_STATUS_IGNORE);
    MPI_Sendrecv(nullptr, 0, MPI_BYTE, west_, tag, nullptr, 0, MPI_BYTE, east_, tag, comm_,
                 MPI_STATUS_IGNORE);
}

double Domain::sendrecv(const void *out, int out_bytes, int dest, void *in, int in_bytes, int src,
                        int tag) {
    const double start = wall_seconds();
    {
        MaybePhase t(timers_, Phase::comm);
        MPI_Sendrecv(out, out_bytes, MPI_BYTE, dest, tag, in, in_bytes, MPI_BYTE, src, tag, comm_,
                     MPI_STATUS_IGNORE);
    }
    const double spent = wall_seconds() - start;
    if (dest != MPI_PROC_NULL) {
        tally_.messages += 1;
        tally_.bytes += out_bytes;
    }
    shift_hockney_s_ += sendrecv_hockney(dest, out_bytes, src, in_bytes);
    return spent;
}

double Domain::sendrecv_hockney(int dest, double out_bytes, int src, double in_bytes) const {
    // Both directions travel at once: the call lasts as long as the longer transfer.
    const MessageCost &to = dest == east_ ? cost_east_ : cost_west_;
    const MessageCost &from = src == east_ ? cost_east_ : cost_west_;
    double t = 0;
    if (dest != MPI_PROC_NULL && to)
        t = to(out_bytes);
    if (src != MPI_PROC_NULL && from)
        t = std::max(t, from(in_bytes));
    return t;
}

template <class T>
Domain::Received<T> Domain::shift(const std::vector<T> &to_west, const std::vector<T> &to_east,
                                  int tag) {
    static_assert(std::is_trivially_copyable_v<T>);
    // Two shifts (eastward, then westward), counts first, values as bytes. Every rank sends
    // and receives at once, so no chain forms across ranks; MPI_PROC_NULL makes the tank
    // edges no-ops.
    const std::size_t k = shift_index(tag);
    if (cpu_segments_ && last_end_cpu_s_ >= 0)
        tally_.segment_cpu_s[k] += thread_cpu_seconds() - last_end_cpu_s_;
    wait_for_neighbours(tag);
    // The compute since the last shifts decides what this one costs on this machine.
    const double start = wall_seconds();
    const auto [since_any, since_kind] = gaps(tag, start);
    shift_hockney_s_ = 0;
    Received<T> in;
    // The transfers alone, as the comm phase times them: sizing a receive buffer between
    // them is the app's work, not the exchange benchmark's.
    double transfers_s = 0;
    auto one_way = [&](int dest, int src, const std::vector<T> &out, std::vector<T> &into) {
        int n_out = static_cast<int>(out.size()), n_in = 0;
        transfers_s += sendrecv(&n_out, sizeof n_out, dest, &n_in, sizeof n_in, src, tag);
        into.resize(static_cast<std::size_t>(src == MPI_PROC_NULL ? 0 : n_in));
        transfers_s += sendrecv(out.data(), n_out * static_cast<int>(sizeof(T)), dest, into.data(),
                                static_cast<int>(into.size() * sizeof(T)), src, tag);
    };
    one_way(east_, west_, to_east, in.from_west);
    one_way(west_, east_, to_west, in.from_east);
    const double end = wall_seconds();
    shift_ended(tag, end);
    if (cpu_segments_)
        last_end_cpu_s_ = thread_cpu_seconds();
    tally_.shift_s[k] += transfers_s;
    const double payload =
        static_cast<double>(sizeof(T) * std::max({to_east.size(), to_west.size(),
                                                  in.from_west.size(), in.from_east.size()}));
    tally_.hockney_s += shift_hockney_s_;
    const ShiftPrediction predicted = shift_cost_
                                          ? shift_cost_(since_any, since_kind, payload)
                                          : ShiftPrediction{shift_hockney_s_, shift_hockney_s_};
    tally_.predicted_s += predicted.seconds;
    tally_.shift_predict_s[k] += predicted.seconds;
    tally_.shift_predict_own_kind_s[k] += predicted.own_kind_gap_s;
    return in;
}

ExchangeCounts Domain::migrate(Particles &p, const std::function<void(std::int64_t)> &forget,
                               bool multi_hop) {
    if (slab_.ranks == 1)
        return {};
    std::optional<MaybePhase> pack(std::in_place, timers_, Phase::pack);
    std::vector<ParticleRecord> to_west, to_east;
    for (std::size_t i = p.owned(); i-- > 0;) {
        const int owner = slab_.owner_of(p.x[i]);
        if (owner == slab_.rank)
            continue;
        if (!multi_hop && owner != slab_.rank - 1 && owner != slab_.rank + 1)
            throw std::runtime_error("particle " + std::to_string(p.id[i]) + " jumped from rank " +
                                     std::to_string(slab_.rank) + " to rank " +
                                     std::to_string(owner) + " in one step; dt is too large");
        (owner < slab_.rank ? to_west : to_east).push_back(p.record(i));
        forget(p.id[i]);
        p.remove_owned(i);
    }
    ExchangeCounts c{to_west.size() + to_east.size(), 0};
    sent_west_ += static_cast<long long>(to_west.size());
    sent_east_ += static_cast<long long>(to_east.size());
    pack.reset();
    const auto in = shift(to_west, to_east, tag_migrate);
    pack.emplace(timers_, Phase::pack);
    recv_west_ += static_cast<long long>(in.from_west.size());
    recv_east_ += static_cast<long long>(in.from_east.size());
    for (const auto *part : {&in.from_west, &in.from_east})
        for (const auto &r : *part)
            p.add_owned(r);
    c.received = in.from_west.size() + in.from_east.size();
    return c;
}

ExchangeCounts Domain::rebalance(Particles &p, std::vector<int> cuts,
                                 const std::function<void(std::int64_t)> &forget) {
    check_cuts(cuts, slab_.ranks, slab_.columns);
    // Every rank must move to the same cuts: a disagreement would lose particles silently.
    const long long mine = std::accumulate(cuts.begin(), cuts.end(), 0LL,
                                           [](long long a, int c) { return a * 31 + c; });
    long long lo = 0, hi = 0;
    MPI_Allreduce(&mine, &lo, 1, MPI_LONG_LONG, MPI_MIN, comm_);
    MPI_Allreduce(&mine, &hi, 1, MPI_LONG_LONG, MPI_MAX, comm_);
    if (lo != hi)
        throw std::logic_error("rebalance: the ranks computed different slab cuts");
    slab_.cuts = std::move(cuts);
    slab_.begin = slab_.cuts[static_cast<std::size_t>(slab_.rank)];
    slab_.end = slab_.cuts[static_cast<std::size_t>(slab_.rank) + 1];
    ExchangeCounts total;
    // Each round moves every particle one slab toward its owner; at most ranks - 1 rounds.
    for (int round = 0; round < slab_.ranks; ++round) {
        const ExchangeCounts c = migrate(p, forget, true);
        total.sent += c.sent;
        total.received += c.received;
        long long misplaced = 0;
        for (std::size_t i = 0; i < p.owned(); ++i)
            misplaced += slab_.owns(p.x[i]) ? 0 : 1;
        if (sum(misplaced) == 0)
            return total;
    }
    throw std::logic_error("rebalance: particles still misplaced after " +
                           std::to_string(slab_.ranks) + " rounds");
}

void Domain::sum_all(std::vector<double> &v) const {
    MPI_Allreduce(MPI_IN_PLACE, v.data(), static_cast<int>(v.size()), MPI_DOUBLE, MPI_SUM, comm_);
}

template <class West, class East>
void Domain::pack_ghosts(const Particles &p, West west, East east) {
    export_west_.clear();
    export_east_.clear();
    const double west_edge = slab_.x_begin() + slab_.cell_size;
    const double east_edge = slab_.x_end() - slab_.cell_size;
    const std::size_t n = p.size();
    for (std::size_t i = 0; i < n; ++i) {
        if (west_ != MPI_PROC_NULL && p.x[i] < west_edge) {
            west(p.record(i));
            export_west_.push_back(static_cast<std::uint32_t>(i));
        }
        if (east_ != MPI_PROC_NULL && p.x[i] >= east_edge) {
            east(p.record(i));
            export_east_.push_back(static_cast<std::uint32_t>(i));
        }
    }
}

void Domain::pack_ghosts(const Particles &p, std::vector<ParticleRecord> &to_west,
                         std::vector<ParticleRecord> &to_east) {
    MaybePhase t(timers_, Phase::pack);
    to_west.clear();
    to_east.clear();
    pack_ghosts(
        p, [&](const ParticleRecord &r) { to_west.push_back(r); },
        [&](const ParticleRecord &r) { to_east.push_back(r); });
}

template <class T> std::pair<T *, T *> Domain::window_buffers() {
    return {reinterpret_cast<T *>(window_->outgoing(0)),
            reinterpret_cast<T *>(window_->outgoing(1))};
}

std::pair<std::span<const ParticleRecord>, std::span<const ParticleRecord>>
Domain::pack_ghosts_into_window(const Particles &p) {
    const auto [west, east] = window_buffers<ParticleRecord>();
    MaybePhase t(timers_, Phase::pack);
    const std::size_t room = window_->capacity() / sizeof(ParticleRecord);
    std::size_t nw = 0, ne = 0;
    auto into = [room](ParticleRecord *buf, std::size_t &n) {
        return [buf, &n, room](const ParticleRecord &r) {
            if (n == room) // the segment holds every particle of the job
                throw std::logic_error("--halo-transport window: more ghosts than particles");
            buf[n++] = r;
        };
    };
    pack_ghosts(p, into(west, nw), into(east, ne));
    return {{west, nw}, {east, ne}};
}

void Domain::land_ghosts(Particles &p, std::span<const ParticleRecord> west,
                         std::span<const ParticleRecord> east) {
    MaybePhase t(timers_, Phase::pack);
    ghosts_begin_ = p.size();
    ghosts_from_west_ = west.size();
    for (const auto part : {west, east})
        for (const auto &r : part)
            p.add_transient(r);
}

template <class T>
std::pair<std::span<const T>, std::span<const T>> Domain::arrived(const Received<T> &in) const {
    if (!window_)
        return {in.from_west, in.from_east};
    auto typed = [](std::span<const std::byte> b) {
        return std::span<const T>(reinterpret_cast<const T *>(b.data()), b.size() / sizeof(T));
    };
    const auto west = typed(flight_.window_in.first), east = typed(flight_.window_in.second);
    // The counts also rode on the handshake: both must tell the same.
    if (west.size() != flight_.recv_west || east.size() != flight_.recv_east)
        throw std::logic_error("--halo-transport window: a payload's size differs from the "
                               "count its handshake announced");
    return {west, east};
}

ExchangeCounts Domain::exchange_ghosts(Particles &p) {
    if (slab_.ranks == 1)
        return {};
    open_window(p);
    if (window_) { // the same post and completion, back to back
        begin_ghosts(p);
        return land_ghosts_posted(p, false);
    }
    std::vector<ParticleRecord> to_west, to_east;
    pack_ghosts(p, to_west, to_east);
    const auto in = shift(to_west, to_east, tag_ghost);
    land_ghosts(p, in.from_west, in.from_east);
    return {to_west.size() + to_east.size(), in.from_west.size() + in.from_east.size()};
}

namespace {
// The densities of the particles `idx`, in order, from `out` on.
void densities_of(const Particles &p, const std::vector<std::uint32_t> &idx, double *out) {
    for (auto i : idx)
        *out++ = p.rho[i];
}
// Into `out`, whose buffer is kept: --overlap packs into the same vectors every step.
void densities_of(const Particles &p, const std::vector<std::uint32_t> &idx,
                  std::vector<double> &out) {
    out.resize(idx.size());
    densities_of(p, idx, out.data());
}
} // namespace

void Domain::refresh_ghost_density(Particles &p) {
    if (slab_.ranks == 1)
        return;
    if (window_) {
        begin_ghost_density(p);
        land_densities_posted(p, false);
        return;
    }
    std::optional<MaybePhase> pack(std::in_place, timers_, Phase::pack);
    // The overlapped path's kept buffers: a run refreshes densities one way or the other.
    densities_of(p, export_west_, flight_.rho_to_west);
    densities_of(p, export_east_, flight_.rho_to_east);
    pack.reset();
    const auto in = shift(flight_.rho_to_west, flight_.rho_to_east, tag_density);
    pack.emplace(timers_, Phase::pack);
    land_densities(p, in.from_west, in.from_east);
}

void Domain::land_densities(Particles &p, std::span<const double> west,
                            std::span<const double> east) const {
    std::copy(west.begin(), west.end(), p.rho.begin() + static_cast<std::ptrdiff_t>(ghosts_begin_));
    std::copy(east.begin(), east.end(),
              p.rho.begin() + static_cast<std::ptrdiff_t>(ghosts_begin_ + ghosts_from_west_));
}

template <class T>
std::pair<std::size_t, std::size_t> Domain::post_shift(std::span<const T> to_west,
                                                       std::span<const T> to_east, Received<T> &in,
                                                       int tag) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (!flight_.receives.empty())
        throw std::logic_error("Domain: an exchange is already in flight");
    // The counts ride on the handshake (the receiver sizes its buffers from them): the wait
    // for the slower neighbour stays apart from the transfers, and no transfer waits here.
    int from_w = 0, from_e = 0;
    {
        MaybePhase t(timers_, Phase::wait);
        const int to_e = static_cast<int>(to_east.size()), to_w = static_cast<int>(to_west.size());
        MPI_Sendrecv(&to_e, 1, MPI_INT, east_, tag, &from_w, 1, MPI_INT, west_, tag, comm_,
                     MPI_STATUS_IGNORE);
        MPI_Sendrecv(&to_w, 1, MPI_INT, west_, tag, &from_e, 1, MPI_INT, east_, tag, comm_,
                     MPI_STATUS_IGNORE);
    }
    const double comm_start = wall_seconds();
    flight_.tag = tag;
    flight_.gaps = gaps(tag, comm_start);
    if (window_) {
        // Already in this rank's segment: posting is storing the sizes and sequence numbers.
        in.from_west.clear();
        in.from_east.clear();
        MaybePhase t(timers_, Phase::comm);
        window_->publish(to_west.size_bytes(), to_east.size_bytes());
        for (const auto &[peer, bytes] :
             {std::pair{west_, to_west.size_bytes()}, std::pair{east_, to_east.size_bytes()}})
            if (peer != MPI_PROC_NULL) {
                tally_.messages += 1;
                tally_.bytes += static_cast<double>(bytes);
            }
    } else {
        in.from_west.resize(static_cast<std::size_t>(west_ == MPI_PROC_NULL ? 0 : from_w));
        in.from_east.resize(static_cast<std::size_t>(east_ == MPI_PROC_NULL ? 0 : from_e));
        MaybePhase t(timers_, Phase::comm);
        // A send completes only once the neighbour's MPI has taken it in (measured: an eager
        // 512 B send waits ~1 ms for a neighbour computing 1 ms), so the previous exchange's
        // sends are completed here, where the handshake shows the neighbour is in MPI.
        MPI_Waitall(static_cast<int>(flight_.sends.size()), flight_.sends.data(),
                    MPI_STATUSES_IGNORE);
        flight_.sends.clear();
        auto post = [&](bool send, const void *buf, void *rbuf, std::size_t count, int peer) {
            if (peer == MPI_PROC_NULL)
                return;
            const int bytes = static_cast<int>(count * sizeof(T));
            MPI_Request r;
            if (send) {
                MPI_Isend(buf, bytes, MPI_BYTE, peer, tag, comm_, &r);
                flight_.sends.push_back(r);
                tally_.messages += 1;
                tally_.bytes += bytes;
            } else {
                MPI_Irecv(rbuf, bytes, MPI_BYTE, peer, tag, comm_, &r);
                flight_.receives.push_back(r);
            }
        };
        post(false, nullptr, in.from_west.data(), in.from_west.size(), west_);
        post(false, nullptr, in.from_east.data(), in.from_east.size(), east_);
        post(true, to_east.data(), nullptr, to_east.size(), east_);
        post(true, to_west.data(), nullptr, to_west.size(), west_);
    }
    tally_.shift_s[shift_index(tag)] += wall_seconds() - comm_start;
    // Hockney of the payloads as the blocking shift costs them.
    auto bytes = [](auto n) {
        return static_cast<double>(static_cast<std::size_t>(n) * sizeof(T));
    };
    const double in_west = bytes(west_ == MPI_PROC_NULL ? 0 : from_w),
                 in_east = bytes(east_ == MPI_PROC_NULL ? 0 : from_e);
    shift_hockney_s_ = sendrecv_hockney(east_, bytes(to_east.size()), west_, in_west) +
                       sendrecv_hockney(west_, bytes(to_west.size()), east_, in_east);
    // What no overlap hides: this rank takes in each received payload itself.
    flight_.exposed_s = 0;
    if (overlap_west_ && west_ != MPI_PROC_NULL)
        flight_.exposed_s += overlap_west_(in_west);
    if (overlap_east_ && east_ != MPI_PROC_NULL)
        flight_.exposed_s += overlap_east_(in_east);
    if (!overlap_west_ && !overlap_east_)
        flight_.exposed_s = shift_hockney_s_;
    flight_.sent_west = to_west.size();
    flight_.sent_east = to_east.size();
    flight_.recv_west = static_cast<std::size_t>(west_ == MPI_PROC_NULL ? 0 : from_w);
    flight_.recv_east = static_cast<std::size_t>(east_ == MPI_PROC_NULL ? 0 : from_e);
    flight_.posted_s = wall_seconds();
    return {flight_.recv_west, flight_.recv_east};
}

void Domain::complete_shift(double payload_bytes, bool overlapped) {
    const double window = wall_seconds() - flight_.posted_s;
    {
        MaybePhase t(timers_, Phase::comm);
        if (window_) {
            const auto [w, e] = window_->incoming();
            flight_.window_in = {{w.data, w.bytes}, {e.data, e.bytes}};
        } else {
            MPI_Waitall(static_cast<int>(flight_.receives.size()), flight_.receives.data(),
                        MPI_STATUSES_IGNORE);
        }
    }
    flight_.receives.clear();
    const double end = wall_seconds();
    shift_ended(flight_.tag, end);
    if (cpu_segments_) // an overlapped shift records no segment
        last_end_cpu_s_ = thread_cpu_seconds();
    const std::size_t k = shift_index(flight_.tag);
    tally_.shift_s[k] += end - flight_.posted_s - window;
    if (overlapped)
        tally_.overlap_s += window;
    tally_.hockney_s += shift_hockney_s_;
    // What stays exposed, predicted. Measured whole when the exchange benchmark ran overlapped
    // (posting and completing the same messages with this much compute behind them: on one node
    // the receiver's copy, the request handling and whatever the compute left cold). Otherwise
    // bounded below: taking in the received payloads, each as long as a hot one-way message of
    // its size (on one node the copy is this core's work, and a large message's single copy
    // starts only when the receiver's MPI sees it), or more if the compute behind the transfers
    // was shorter than the rest of what the shift costs after compute (exchange benchmark:
    // synchronisation, cold caches). The rest is hidden (the thesis' T_overlap).
    const double blocking =
        shift_cost_ ? shift_cost_(flight_.gaps.first, flight_.gaps.second, payload_bytes).seconds
                    : shift_hockney_s_;
    const double exposed =
        exposed_cost_ ? exposed_cost_(window, payload_bytes)
                      : std::max(flight_.exposed_s, std::max(blocking, flight_.exposed_s) - window);
    tally_.predicted_s += exposed;
    tally_.shift_predict_s[k] += exposed;
    tally_.shift_predict_own_kind_s[k] += exposed;
    if (overlapped)
        tally_.hidden_predict_s += std::max(0.0, blocking - exposed);
}

void Domain::complete_sends() {
    MPI_Waitall(static_cast<int>(flight_.sends.size()), flight_.sends.data(), MPI_STATUSES_IGNORE);
    flight_.sends.clear();
}

GhostsInFlight Domain::begin_ghosts(const Particles &p) {
    if (slab_.ranks == 1)
        return {};
    open_window(p);
    std::span<const ParticleRecord> west, east;
    if (window_) {
        std::tie(west, east) = pack_ghosts_into_window(p);
    } else {
        pack_ghosts(p, flight_.to_west, flight_.to_east);
        west = flight_.to_west;
        east = flight_.to_east;
    }
    const auto [from_w, from_e] = post_shift(west, east, flight_.ghosts, tag_ghost);
    return {from_w, from_e};
}

ExchangeCounts Domain::finish_ghosts(Particles &p) {
    if (slab_.ranks == 1) {
        ghosts_begin_ = p.size();
        ghosts_from_west_ = 0;
        return {};
    }
    return land_ghosts_posted(p, true);
}

ExchangeCounts Domain::land_ghosts_posted(Particles &p, bool overlapped) {
    complete_shift(static_cast<double>(sizeof(ParticleRecord) * flight_.largest()), overlapped);
    const auto [west, east] = arrived(flight_.ghosts);
    land_ghosts(p, west, east);
    return {flight_.sent_west + flight_.sent_east, west.size() + east.size()};
}

void Domain::begin_ghost_density(const Particles &p) {
    if (slab_.ranks == 1)
        return;
    std::span<const double> west, east;
    if (window_) {
        const auto [w, e] = window_buffers<double>();
        MaybePhase t(timers_, Phase::pack);
        densities_of(p, export_west_, w); // an export list is empty without its neighbour
        densities_of(p, export_east_, e);
        west = {w, export_west_.size()};
        east = {e, export_east_.size()};
    } else {
        MaybePhase t(timers_, Phase::pack);
        densities_of(p, export_west_, flight_.rho_to_west);
        densities_of(p, export_east_, flight_.rho_to_east);
        west = flight_.rho_to_west;
        east = flight_.rho_to_east;
    }
    post_shift(west, east, flight_.rho, tag_density);
}

void Domain::finish_ghost_density(Particles &p) {
    if (slab_.ranks == 1)
        return;
    land_densities_posted(p, true);
}

void Domain::land_densities_posted(Particles &p, bool overlapped) {
    complete_shift(static_cast<double>(sizeof(double) * flight_.largest()), overlapped);
    MaybePhase t(timers_, Phase::pack);
    const auto [west, east] = arrived(flight_.rho);
    land_densities(p, west, east);
}

double Domain::sum(double v) const {
    double out = 0;
    MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_SUM, comm_);
    return out;
}
double Domain::max(double v) const {
    double out = 0;
    MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_MAX, comm_);
    return out;
}
long long Domain::sum(long long v) const {
    long long out = 0;
    MPI_Allreduce(&v, &out, 1, MPI_LONG_LONG, MPI_SUM, comm_);
    return out;
}
void Domain::sum_to_root(std::vector<double> &v) const {
    if (slab_.rank == 0)
        MPI_Reduce(MPI_IN_PLACE, v.data(), static_cast<int>(v.size()), MPI_DOUBLE, MPI_SUM, 0,
                   comm_);
    else
        MPI_Reduce(v.data(), nullptr, static_cast<int>(v.size()), MPI_DOUBLE, MPI_SUM, 0, comm_);
}
std::vector<double> Domain::gather(const std::vector<double> &v) const {
    std::vector<double> out(slab_.rank == 0 ? v.size() * static_cast<std::size_t>(slab_.ranks) : 0);
    MPI_Gather(v.data(), static_cast<int>(v.size()), MPI_DOUBLE, out.data(),
               static_cast<int>(v.size()), MPI_DOUBLE, 0, comm_);
    return out;
}
void Domain::barrier() const {
    MPI_Barrier(comm_);
}
std::vector<int> Domain::gather_int(int v) const {
    std::vector<int> out(static_cast<std::size_t>(slab_.ranks));
    MPI_Allgather(&v, 1, MPI_INT, out.data(), 1, MPI_INT, comm_);
    return out;
}

std::vector<std::string> Domain::gather_string(const std::string &v) const {
    constexpr std::size_t width = 256;
    std::vector<char> mine(width, '\0'), all(width * static_cast<std::size_t>(slab_.ranks));
    std::copy_n(v.begin(), std::min(v.size(), width - 1), mine.begin());
    MPI_Allgather(mine.data(), static_cast<int>(width), MPI_CHAR, all.data(),
                  static_cast<int>(width), MPI_CHAR, comm_);
    std::vector<std::string> out;
    for (int r = 0; r < slab_.ranks; ++r)
        out.emplace_back(&all[static_cast<std::size_t>(r) * width]);
    return out;
}

} // namespace sphperf::sph
