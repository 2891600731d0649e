#pragma once
// Domain decomposition and communication: the only code that calls MPI. The tank is cut into
// vertical slabs of whole cell columns in rank order (thesis 3.1); each step, particles that
// left a slab migrate and the particles of each edge column are sent as ghosts. One rank
// exchanges nothing.
#include "sphperf/sph/balance.hpp"
#include "sphperf/sph/grid.hpp"
#include "sphperf/sph/particles.hpp"
#include "sphperf/sph/timers.hpp"

#include <mpi.h>

#include <algorithm>
#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace sphperf::sph {

struct Slab {
    int rank = 0, ranks = 1;
    int columns = 1;        // cell columns over the whole tank
    int begin = 0, end = 1; // the columns this rank owns
    double cell_size = 1;
    std::vector<int> cuts{0, 1}; // every rank's first column, then `columns` (balance.hpp)

    static int first_column(int rank, int ranks, int columns) {
        return static_cast<int>(static_cast<long long>(rank) * columns / ranks);
    }
    int owner_of_column(int column) const;
    int owner_of(double x) const; // positions outside the tank belong to the edge ranks
    bool owns(double x) const { return owner_of(x) == rank; }
    double x_begin() const { return begin * cell_size; }
    double x_end() const { return end * cell_size; }
};

struct ExchangeCounts {
    std::size_t sent = 0, received = 0;
};

// What this rank sent since the last take_tally(): messages, payload bytes, and, when costs
// are attached, the predicted time of their transfer: per message by ping-pong Hockney (the
// thesis' T_COMM_PREDICT), and per shift by the exchange benchmark (falls back to Hockney).
// shift_s: the comm phase split by exchange (Shift), and shift_predict_s the predicted part of
// each (they sum to predicted_s), shift_predict_own_kind_s the same by the rule before session
// 32 (ShiftPrediction). With --overlap also the compute that ran while transfers were in
// flight (`overlap_s`) and, when costs are attached, the predicted part of those transfers it hid
// (`hidden_predict_s`). segment_cpu_s: the CPU time this rank's thread spent between the end of
// its previous blocking shift and the start of each blocking shift (its compute before the
// migration, the ghosts and the densities), what a time-shared step's replay takes in.
struct CommTally {
    double messages = 0, bytes = 0, hockney_s = 0, predicted_s = 0;
    double overlap_s = 0, hidden_predict_s = 0;
    ShiftTimes shift_s{}, shift_predict_s{}, shift_predict_own_kind_s{}, segment_cpu_s{};
};

// Ghosts on their way (--overlap): how many will arrive from each side.
struct GhostsInFlight {
    std::size_t from_west = 0, from_east = 0;
};

// One-way time of a message of `bytes` to or from a neighbour (west or east).
using MessageCost = std::function<double(double bytes)>;
// Time of one whole shift (counts and payloads both ways) `since_any_s` after this rank's
// previous shift and `since_kind_s` after its previous one of the same kind, with payloads of
// `bytes`; beside it the same by the rule before session 32 (model::GapRule::own_kind_gap),
// recorded as the untuned comparison.
struct ShiftPrediction {
    double seconds = 0, own_kind_gap_s = 0;
};
using ShiftCost =
    std::function<ShiftPrediction(double since_any_s, double since_kind_s, double bytes)>;
class HaloWindow; // domain.cpp: ghosts and densities through a shared-memory window

// What an overlapped shift leaves exposed (posting and completion) with `behind_s` of compute
// behind its transfers and `bytes` per payload (exchange --overlapped).
using ExposedCost = std::function<double(double behind_s, double bytes)>;

class Domain {
public:
    Domain(MPI_Comm comm, int columns, double cell_size);
    ~Domain();
    Domain(const Domain &) = delete;
    Domain &operator=(const Domain &) = delete;

    // sph --halo-transport window (collective; every rank on one node, else std::runtime_error):
    // the ghosts and their densities go through an MPI-3 shared-memory window instead of
    // messages. Each rank packs them straight into its own segment and lands its neighbours'
    // straight from theirs, so no copy is made in between; the migration stays a message.
    // Takes effect at the first ghost exchange, whose particles bound every payload (twice all
    // of the job's: a rank sends at most what it holds, mirrors included).
    void use_window_halo() { window_wanted_ = slab_.ranks > 1; }

    // Where the exchanges' time goes: wait (for a slower neighbour), comm (the transfers), pack
    // (selecting and copying particles). Without timers nothing is timed.
    void attach_timers(PhaseTimers *timers) { timers_ = timers; }
    // Costs messages to the west and east neighbours (sph --machine); empty: no prediction.
    void attach_cost(MessageCost west, MessageCost east) {
        cost_west_ = std::move(west);
        cost_east_ = std::move(east);
    }
    void attach_shift_cost(ShiftCost c) { shift_cost_ = std::move(c); }
    // Records the CPU time before each blocking shift (CommTally::segment_cpu_s; sph --machine
    // only: two clock reads of about 0.5 us per shift on this VM, not paid without it).
    void enable_cpu_segments() { cpu_segments_ = true; }
    // What an overlapped exchange cannot hide of a message received from the west and east
    // neighbours.
    void attach_overlap_cost(MessageCost west, MessageCost east) {
        overlap_west_ = std::move(west);
        overlap_east_ = std::move(east);
    }
    // The overlapped shift as measured whole; when attached it replaces the per-message bound.
    void attach_exposed_cost(ExposedCost c) { exposed_cost_ = std::move(c); }
    CommTally take_tally() { return std::exchange(tally_, CommTally{}); }
    // The machine's latency mode now (sph --machine within the cores): the mean time of 64
    // back-to-back 64-byte shifts after 64 untimed ones, the exchange benchmark's gap-0 point,
    // timed apart from every phase and tally. On this VM it flips between two modes as the
    // hypervisor moves the virtual cores (model/NOTES.md, session 19). 0 unless enabled or alone.
    void enable_latency_probe() { probe_ = true; }
    double probe_latency();
    int west() const { return west_; }
    int east() const { return east_; }

    int rank() const { return slab_.rank; }
    int ranks() const { return slab_.ranks; }
    const Slab &slab() const { return slab_; }
    // The cells this rank stores (slab_window of its columns).
    CellWindow window(int cell_rows) const;

    // Sends owned particles whose column now belongs to another rank; `forget` is told each id
    // that leaves (the persistent grid drops it). Needs no transient particles present. A
    // particle more than one slab away is an error (dt too large), except within rebalance().
    ExchangeCounts migrate(Particles &p, const std::function<void(std::int64_t)> &forget,
                           bool multi_hop = false);
    // Moves the cuts (the same on every rank; checked) and migrates every owned particle to its
    // new owner, hop by hop, until none is left to move. Needs no transient particles present;
    // the caller rebuilds its grid for the new window.
    ExchangeCounts rebalance(Particles &p, std::vector<int> cuts,
                             const std::function<void(std::int64_t)> &forget);
    // Element-wise sum on every rank.
    void sum_all(std::vector<double> &v) const;
    // Appends copies of the neighbours' edge-column particles (owned and mirrors).
    ExchangeCounts exchange_ghosts(Particles &p);
    // Sends the current density of the particles exported by the last exchange_ghosts, so the
    // ghosts match their owners after the owners advanced their density.
    void refresh_ghost_density(Particles &p);
    // The same two exchanges split (--overlap): begin_ swaps the counts with the handshake and
    // posts the payloads; the caller computes what needs no ghost; finish_ waits for them and
    // lands them exactly where the blocking calls do. One exchange in flight at a time; its
    // sends complete at the next begin_, or at complete_sends() (before the run ends).
    GhostsInFlight begin_ghosts(const Particles &p);
    ExchangeCounts finish_ghosts(Particles &p);
    void begin_ghost_density(const Particles &p);
    void finish_ghost_density(Particles &p);
    void complete_sends();
    // Where finish_ghosts put the ghosts: p[ghosts_begin(), p.size()).
    std::size_t ghosts_begin() const { return ghosts_begin_; }

    // Collective helpers.
    double sum(double v) const;
    double max(double v) const;
    long long sum(long long v) const;
    void sum_to_root(std::vector<double> &v) const; // element-wise, result on rank 0
    std::vector<double> gather(const std::vector<double> &v) const; // concatenated on rank 0
    void barrier() const;
    std::vector<int> gather_int(int v) const; // rank order, on every rank
    // Every rank's string (rank order, on every rank); names longer than 255 bytes are cut.
    std::vector<std::string> gather_string(const std::string &v) const;

    // Cumulative migration tallies, for naming the ranks when a particle goes missing.
    long long sent_east() const { return sent_east_; }
    long long sent_west() const { return sent_west_; }
    long long received_east() const { return recv_east_; }
    long long received_west() const { return recv_west_; }

private:
    template <class T> struct Received { std::vector<T> from_west, from_east; };
    template <class T>
    Received<T> shift(const std::vector<T> &to_west, const std::vector<T> &to_east, int tag);
    // A shift in two halves: counts now, payloads posted; then the wait for them.
    // Returns the counts coming from the west and east.
    template <class T>
    std::pair<std::size_t, std::size_t>
    post_shift(std::span<const T> to_west, std::span<const T> to_east, Received<T> &into, int tag);
    // `overlapped`: compute ran between posting and completing (booked as overlap_s); false
    // for the window's blocking exchanges, posted and completed back to back.
    void complete_shift(double payload_bytes, bool overlapped);
    // The posted ghost or density exchange completed and landed.
    ExchangeCounts land_ghosts_posted(Particles &p, bool overlapped);
    void land_densities_posted(Particles &p, bool overlapped);
    // Packing of the ghost exchange, shared by the blocking and the split form.
    // Each particle of the edge columns to `west(record)` and `east(record)`, its index to the
    // export lists.
    template <class West, class East> void pack_ghosts(const Particles &p, West west, East east);
    void pack_ghosts(const Particles &p, std::vector<ParticleRecord> &to_west,
                     std::vector<ParticleRecord> &to_east);
    // --halo-transport window: packed straight into this rank's segment.
    std::pair<std::span<const ParticleRecord>, std::span<const ParticleRecord>>
    pack_ghosts_into_window(const Particles &p);
    void land_ghosts(Particles &p, std::span<const ParticleRecord> west,
                     std::span<const ParticleRecord> east);
    // Received ghost densities into the ghosts' slots.
    void land_densities(Particles &p, std::span<const double> west,
                        std::span<const double> east) const;
    // What complete_shift brought: the received vectors, or the neighbours' window segments.
    template <class T>
    std::pair<std::span<const T>, std::span<const T>> arrived(const Received<T> &in) const;
    // --halo-transport window: this rank's buffers toward the west and east for the next post
    // (nullptr where there is no neighbour).
    template <class T> std::pair<T *, T *> window_buffers();
    void wait_for_neighbours(int tag);
    // A zero-byte message each way with both neighbours, untimed: returns once both arrived.
    void handshake(int tag) const;
    // Hockney time of one MPI_Sendrecv to `dest` and from `src` (0 without costs attached).
    double sendrecv_hockney(int dest, double out_bytes, int src, double in_bytes) const;
    // One MPI_Sendrecv of raw bytes, timed as comm and tallied; returns its seconds.
    double sendrecv(const void *out, int out_bytes, int dest, void *in, int in_bytes, int src,
                    int tag);
    PhaseTimers *timers_ = nullptr;
    MessageCost cost_west_, cost_east_, overlap_west_, overlap_east_;
    ShiftCost shift_cost_;
    ExposedCost exposed_cost_;
    bool probe_ = false;
    bool cpu_segments_ = false;
    // When this rank's previous shift of any kind, and of each kind (migration, ghosts,
    // densities), ended (wall clock): what a shift costs depends on both
    // (model::ExchangeModel::app_shift_seconds).
    double last_any_end_s_ = 0;
    ShiftTimes last_kind_end_s_{};
    double last_end_cpu_s_ = -1; // the thread's CPU time then (-1: no shift yet)
    double &last_end(int tag) { return last_kind_end_s_[shift_index(tag)]; }
    static std::size_t shift_index(int tag);
    // The gaps since both, at `now`, as the shift cost takes them; 0 before the first.
    std::pair<double, double> gaps(int tag, double now);
    // Records the end of a shift of this kind.
    void shift_ended(int tag, double when);
    double shift_hockney_s_ = 0; // Hockney prediction of the current shift's messages
    CommTally tally_;
    std::vector<std::uint32_t> export_west_, export_east_; // indices sent by the last exchange
    std::size_t ghosts_begin_ = 0, ghosts_from_west_ = 0;  // where received ghosts landed
    // The split exchange in flight: its buffers (alive until completed), requests, and when it
    // was posted.
    struct InFlight {
        std::vector<ParticleRecord> to_west, to_east;
        Received<ParticleRecord> ghosts;
        std::vector<double> rho_to_west, rho_to_east;
        Received<double> rho;
        std::vector<MPI_Request> receives, sends;
        // Particles or densities posted to and coming from each side.
        std::size_t sent_west = 0, sent_east = 0, recv_west = 0, recv_east = 0;
        std::size_t largest() const {
            return std::max({sent_west, sent_east, recv_west, recv_east});
        }
        // --halo-transport window: the payloads from the west and east, in their segments.
        std::pair<std::span<const std::byte>, std::span<const std::byte>> window_in;
        double posted_s = 0, exposed_s = 0; // exposed_s: unhidden, predicted
        std::pair<double, double> gaps;     // since any shift, since one of this kind
        int tag = 0;
    } flight_;
    std::unique_ptr<HaloWindow> window_;
    bool window_wanted_ = false;
    void open_window(const Particles &p); // at the first ghost exchange, when wanted
    MPI_Comm comm_;
    Slab slab_;
    int west_ = MPI_PROC_NULL, east_ = MPI_PROC_NULL;
    long long sent_east_ = 0, sent_west_ = 0, recv_east_ = 0, recv_west_ = 0;
};

} // namespace sphperf::sph
