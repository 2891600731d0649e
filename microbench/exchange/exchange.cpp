// The SPH proxy's halo exchange as a benchmark: ranks in a chain (one slab each), a fixed amount
// of work between exchanges, then exactly the app's shift (a zero-byte handshake with both
// neighbours, then a count and a payload MPI_Sendrecv eastward, then westward). A hot ping-pong
// loop measures none of what the app pays: on this VM a shift after milliseconds of compute
// costs several times the same shift in a tight loop, with a heavy tail, and above the core
// count the ranks take turns. So this measures the shift's cost per (ranks, gap, payload) as
// the app meets it, mean beside median (the model predicts sums, so it uses the mean), and the
// throughput lost to time-sharing. With --following also a shift that comes right after another
// one (the app's ghost shift, after its migration): on some hosts the shift before it warms
// the path and it costs far less than the same shift after compute alone. With --overlapped
// also the shift of sph --overlap (counts on the handshake, payloads posted, the work behind
// them, receives completed): only posting and completion are timed, the part no overlap hides,
// by the compute behind the transfers.
#include "mpi_program.hpp"
#include "sphperf/cli.hpp"
#include "sphperf/report.hpp"
#include "sphperf/stats.hpp"
#include "sphperf/timer.hpp"
#include "sphperf/topology.hpp"

#include <mpi.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>
#include <vector>

namespace {

using namespace sphperf;

constexpr int tag_shift = 7;
constexpr int warmup_rounds = 3;
constexpr double calibration_s = 0.05; // work-rate calibration on rank 0 alone
constexpr int lead_bytes = 64;         // the shift before a following one: a few migrants

// What one point measures: the shift after the work; the shift after the work and another
// shift (the app's ghosts after its migration); the exposed part of an overlapped shift.
enum class Mode { blocking, following, overlapped };
const char *mode_name(Mode m) {
    switch (m) {
    case Mode::following:
        return "following";
    case Mode::overlapped:
        return "overlapped";
    default:
        return "blocking";
    }
}

struct Config {
    // Up to 30 ms: the table grid's dam break at scale 2 computes 31 ms per step (session 19).
    std::vector<double> gaps_us{0, 100, 300, 1000, 3000, 10000, 30000};
    std::vector<int> payload_bytes{64, 1024, 16384};
    double seconds_per_point = 0.3;
    int min_rounds = 20;
    int max_rounds = 2000;
    std::int64_t work_bytes = std::int64_t{2} << 20;
    std::optional<std::filesystem::path> json;
    bool quiet = false;
    bool following = false;
    bool overlapped = false;
};

Config parse(int argc, char **argv) {
    Config cfg;
    cli::App app{"The SPH proxy's halo exchange (handshake, then count + payload MPI_Sendrecv "
                 "east, then west, along a chain of ranks) after a fixed amount of work per "
                 "exchange: cost per shift (mean, median, p90) by compute gap and payload, and "
                 "the throughput lost to time-sharing above the core count. Run under "
                 "scripts/mpirun.sh with >= 2 ranks, once per rank count the model should know."};
    app.always_capture_default();
    app.add_option("--gaps-us", cfg.gaps_us,
                   "Work between exchanges, in microseconds of one rank "
                   "running alone")
        ->check(Finite & cli::Range(0.0, 1e6))
        ->delimiter(',');
    app.add_option("--payload-bytes", cfg.payload_bytes, "Payload of each Sendrecv (bytes)")
        ->check(cli::Range(1, 1 << 26))
        ->delimiter(',');
    app.add_option("--seconds-per-point", cfg.seconds_per_point,
                   "Time spent per (gap, payload) point, about")
        ->check(Finite & cli::Range(1e-3, 600.0));
    app.add_option("--min-rounds", cfg.min_rounds, "Exchanges timed per point at least")
        ->check(cli::Range(5, 1000000));
    app.add_option("--max-rounds", cfg.max_rounds, "Exchanges timed per point at most")
        ->check(cli::Range(5, 1000000));
    app.add_option("--work-bytes", cfg.work_bytes,
                   "Buffer the work streams through per rank (cache footprint of the compute)")
        ->check(cli::Range(std::int64_t{4096}, std::int64_t{1} << 32));
    app.add_flag("--following", cfg.following,
                 "Also measure a shift that follows another: the work, a " +
                     std::to_string(lead_bytes) +
                     "-byte shift (the app's migration, untimed), then the timed shift (its "
                     "points carry \"follows_shift\": true; their gap runs from the previous "
                     "timed shift, so it holds the work and the shift before)");
    app.add_flag("--overlapped", cfg.overlapped,
                 "Also measure the overlapped exchange of sph --overlap: counts on the "
                 "handshake, payloads posted non-blocking, the work behind them, then the "
                 "receives completed (its points carry \"overlapped\": true and the work as "
                 "their gap)");
    app.add_option("--json", cfg.json, "Write the JSON report to this file");
    app.add_flag("--quiet", cfg.quiet, "No progress lines on stderr");
    parse_cli(app, argc, argv);
    if (cfg.max_rounds < cfg.min_rounds)
        throw UsageError("--max-rounds " + std::to_string(cfg.max_rounds) +
                         " is below --min-rounds " + std::to_string(cfg.min_rounds));
    std::sort(cfg.gaps_us.begin(), cfg.gaps_us.end());
    std::sort(cfg.payload_bytes.begin(), cfg.payload_bytes.end());
    return cfg;
}

// Deterministic work: passes over a private buffer with a few flops per element, so that a
// unit costs the same on every rank and time-sharing shows as longer wall time.
class Work {
public:
    explicit Work(std::int64_t bytes) : buf_(static_cast<std::size_t>(bytes) / sizeof(double)) {
        std::iota(buf_.begin(), buf_.end(), 1.0);
    }
    // `elements` element updates, wrapping around the buffer.
    void run(std::int64_t elements) {
        const std::size_t n = buf_.size();
        double acc = sink_;
        while (elements > 0) {
            const std::size_t k =
                std::min<std::size_t>(n - pos_, static_cast<std::size_t>(elements));
            for (std::size_t i = pos_; i < pos_ + k; ++i) {
                buf_[i] = buf_[i] * 0.999999 + 1e-6;
                acc += std::sqrt(buf_[i]);
            }
            elements -= static_cast<std::int64_t>(k);
            pos_ = (pos_ + k) % n;
        }
        sink_ = acc;
    }
    double sink() const { return sink_; }

private:
    std::vector<double> buf_;
    std::size_t pos_ = 0;
    double sink_ = 0;
};

// Waits at a barrier without spinning (spinning ranks would steal the cores of the others).
void quiet_barrier(MPI_Comm comm) {
    MPI_Request req;
    MPI_Ibarrier(comm, &req);
    for (int done = 0;;) {
        MPI_Test(&req, &done, MPI_STATUS_IGNORE);
        if (done)
            return;
        usleep(200);
    }
}

struct Chain {
    int west = MPI_PROC_NULL, east = MPI_PROC_NULL;
};

// The app's shift (sph/src/domain.cpp Domain::shift): handshake, then count and payload each way.
struct ShiftTimes {
    double wait_s = 0, comm_s = 0, behind_s = 0; // behind_s: work while the payloads travel
};
ShiftTimes shift(const Chain &c, std::vector<char> &out, std::vector<char> &in) {
    const double t0 = wall_seconds();
    MPI_Sendrecv(nullptr, 0, MPI_BYTE, c.east, tag_shift, nullptr, 0, MPI_BYTE, c.west, tag_shift,
                 MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    MPI_Sendrecv(nullptr, 0, MPI_BYTE, c.west, tag_shift, nullptr, 0, MPI_BYTE, c.east, tag_shift,
                 MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    const double t1 = wall_seconds();
    const int bytes = static_cast<int>(out.size());
    for (const auto &[dest, src] : {std::pair{c.east, c.west}, std::pair{c.west, c.east}}) {
        int n_out = bytes, n_in = 0;
        MPI_Sendrecv(&n_out, 1, MPI_INT, dest, tag_shift, &n_in, 1, MPI_INT, src, tag_shift,
                     MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        MPI_Sendrecv(out.data(), dest == MPI_PROC_NULL ? 0 : bytes, MPI_BYTE, dest, tag_shift,
                     in.data(), src == MPI_PROC_NULL ? 0 : bytes, MPI_BYTE, src, tag_shift,
                     MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    }
    return {t1 - t0, wall_seconds() - t1};
}

// The app's overlapped shift (Domain::post_shift / complete_shift): the counts ride on the
// handshake, the payloads are posted (after completing the previous round's sends), `behind`
// runs while they travel, then the receives complete. Only the posting and the completion are
// communication: what an overlap leaves exposed.
class OverlappedShift {
public:
    template <class Behind>
    ShiftTimes run(const Chain &c, std::vector<char> &out, std::vector<char> &in, Behind behind) {
        in_east_.resize(in.size()); // both receives are in flight at once
        const double t0 = wall_seconds();
        const int bytes = static_cast<int>(out.size());
        int from_w = 0, from_e = 0;
        MPI_Sendrecv(&bytes, 1, MPI_INT, c.east, tag_shift, &from_w, 1, MPI_INT, c.west, tag_shift,
                     MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        MPI_Sendrecv(&bytes, 1, MPI_INT, c.west, tag_shift, &from_e, 1, MPI_INT, c.east, tag_shift,
                     MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        const double t1 = wall_seconds();
        MPI_Waitall(static_cast<int>(sends_.size()), sends_.data(), MPI_STATUSES_IGNORE);
        sends_.clear();
        receives_.clear(); // kept: no allocation inside the timed posting, as in the app
        auto post = [&](bool send, void *buf, int peer) {
            if (peer == MPI_PROC_NULL)
                return;
            MPI_Request r;
            if (send) {
                MPI_Isend(buf, bytes, MPI_BYTE, peer, tag_shift, MPI_COMM_WORLD, &r);
                sends_.push_back(r);
            } else {
                MPI_Irecv(buf, bytes, MPI_BYTE, peer, tag_shift, MPI_COMM_WORLD, &r);
                receives_.push_back(r);
            }
        };
        post(false, in.data(), c.west);
        post(false, in_east_.data(), c.east);
        post(true, out.data(), c.east);
        post(true, out.data(), c.west);
        const double t2 = wall_seconds();
        behind();
        const double t3 = wall_seconds();
        MPI_Waitall(static_cast<int>(receives_.size()), receives_.data(), MPI_STATUSES_IGNORE);
        const double t4 = wall_seconds();
        return {t1 - t0, (t2 - t1) + (t4 - t3), t3 - t2};
    }
    void finish() {
        MPI_Waitall(static_cast<int>(sends_.size()), sends_.data(), MPI_STATUSES_IGNORE);
        sends_.clear();
    }

private:
    std::vector<MPI_Request> sends_, receives_;
    std::vector<char> in_east_;
};

struct Point {
    Mode mode = Mode::blocking;
    double gap_work_us = 0, payload_bytes = 0, rounds = 0;
    std::int64_t work_elements = 0; // the work of one round: gap_work_us x elements per us
    Summary shift;                  // comm per shift, over all ranks and rounds
    double shift_p90_s = 0;
    // End of the previous shift to the first transfer (work + wait); overlapped: the work
    // behind the transfers, which is what the app knows when it completes them.
    double gap_s_mean = 0;
    double work_s_mean = 0; // the work's wall time (longer than alone when ranks take turns)
    double wait_s_mean = 0;
    double round_s_mean = 0; // wall time per exchange round, slowest rank
};

Point measure(const Config &cfg, const Chain &chain, Work &work, double elements_per_us,
              double gap_us, int bytes, int size, int cores, Mode mode) {
    const auto elements = static_cast<std::int64_t>(std::llround(gap_us * elements_per_us));
    // Estimated round length, assuming the ranks share the cores fairly.
    const double round_guess_s =
        std::max(20e-6, gap_us * 1e-6 * std::max(1.0, static_cast<double>(size) / cores));
    const int rounds = std::clamp(static_cast<int>(cfg.seconds_per_point / round_guess_s),
                                  cfg.min_rounds, cfg.max_rounds);
    std::vector<char> out(static_cast<std::size_t>(bytes), 'x'), in(out.size());
    std::vector<char> lead_out(lead_bytes, 'y'), lead_in(lead_bytes);
    const bool overlapped = mode == Mode::overlapped;
    OverlappedShift ovl;
    // One round: the work, then the shift (following: another shift between them, as the
    // app's migration before its ghosts); overlapped, the work runs behind the transfers.
    auto round = [&] {
        if (overlapped)
            return ovl.run(chain, out, in, [&] { work.run(elements); });
        const double t0 = wall_seconds();
        work.run(elements);
        double lead_s = 0;
        if (mode == Mode::following) {
            const ShiftTimes lead = shift(chain, lead_out, lead_in);
            lead_s = lead.wait_s + lead.comm_s;
        }
        ShiftTimes s = shift(chain, out, in);
        s.behind_s = wall_seconds() - t0 - lead_s - s.wait_s - s.comm_s;
        return s;
    };
    quiet_barrier(MPI_COMM_WORLD);
    for (int i = 0; i < warmup_rounds; ++i)
        round();
    std::vector<double> comm, gap, work_t, wait;
    double prev_end = wall_seconds();
    const double start = prev_end;
    for (int i = 0; i < rounds; ++i) {
        const ShiftTimes s = round();
        const double end = wall_seconds();
        work_t.push_back(s.behind_s);
        wait.push_back(s.wait_s);
        comm.push_back(s.comm_s);
        gap.push_back(overlapped ? s.behind_s : end - s.comm_s - prev_end);
        prev_end = end;
    }
    ovl.finish();
    const double elapsed = prev_end - start;
    // Everything to rank 0: every rank's samples count (edge ranks send or receive only).
    auto gather = [&](const std::vector<double> &v) {
        std::vector<double> all(static_cast<std::size_t>(size) * v.size());
        MPI_Gather(v.data(), static_cast<int>(v.size()), MPI_DOUBLE, all.data(),
                   static_cast<int>(v.size()), MPI_DOUBLE, 0, MPI_COMM_WORLD);
        return all;
    };
    const auto comm_all = gather(comm), gap_all = gather(gap), work_all = gather(work_t),
               wait_all = gather(wait);
    double slowest = 0;
    MPI_Reduce(&elapsed, &slowest, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    Point p;
    p.mode = mode;
    p.gap_work_us = gap_us;
    p.work_elements = elements;
    p.payload_bytes = bytes;
    p.rounds = rounds;
    p.shift = summarize(comm_all);
    if (!comm_all.empty()) {
        auto sorted = comm_all;
        std::sort(sorted.begin(), sorted.end());
        p.shift_p90_s = sorted[sorted.size() * 9 / 10];
    }
    auto mean = [](const std::vector<double> &v) {
        return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / v.size();
    };
    p.gap_s_mean = mean(gap_all);
    p.work_s_mean = mean(work_all);
    p.wait_s_mean = mean(wait_all);
    p.round_s_mean = slowest / rounds;
    return p;
}

// Element updates per microsecond of one rank alone: rank 0 times the work while the others
// sleep, then tells them, so every rank does the same work per gap.
double calibrate(Work &work, int rank) {
    double rate = 0;
    if (rank == 0) {
        std::int64_t n = 1 << 14;
        for (;;) {
            const double t0 = wall_seconds();
            work.run(n);
            const double t = wall_seconds() - t0;
            if (t >= calibration_s) {
                rate = static_cast<double>(n) / (t * 1e6);
                break;
            }
            n *= 2;
        }
    }
    quiet_barrier(MPI_COMM_WORLD);
    MPI_Bcast(&rate, 1, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    return rate;
}

nlohmann::json point_json(const Point &p, int size, int cores) {
    // Time-sharing: R ranks on C cores need at least ceil(R/C) x the work's time alone per
    // round (the busiest core serves that many, bound round-robin by scripts/mpirun.sh or
    // placed by the scheduler); the overhead is the measured round over that bound (context
    // switches, ranks waiting for a descheduled neighbour, the shift itself).
    const double share = std::max(1.0, std::ceil(static_cast<double>(size) / cores));
    const double ideal = p.gap_work_us * 1e-6 * share;
    return {
        {"overlapped", p.mode == Mode::overlapped},
        {"follows_shift", p.mode == Mode::following},
        {"gap_work_us", p.gap_work_us},
        {"work_elements", p.work_elements},
        {"payload_bytes", p.payload_bytes},
        {"rounds", p.rounds},
        {"gap_s_mean", p.gap_s_mean},
        {"work_s_mean", p.work_s_mean},
        {"wait_s_mean", p.wait_s_mean},
        {"round_s_mean", p.round_s_mean},
        {"round_overhead", ideal > 0 ? nlohmann::json(p.round_s_mean / ideal) : nlohmann::json()},
        {"shift",
         {{"mean_s", p.shift.avg},
          {"median_s", p.shift.median},
          {"p90_s", p.shift_p90_s},
          {"min_s", p.shift.min},
          {"max_s", p.shift.max},
          {"samples", p.shift.count}}}};
}

int run(int argc, char **argv, int rank, int size) {
    const Topology topo;
    const Config cfg = parse(argc, argv);
    require_ranks("exchange", size);
    check_report_path_on_root(cfg.json, rank);

    const int cores = topo.cores();
    Chain chain;
    if (rank > 0)
        chain.west = rank - 1;
    if (rank + 1 < size)
        chain.east = rank + 1;
    Work work(cfg.work_bytes);
    const double rate = calibrate(work, rank);
    nlohmann::json points = nlohmann::json::array();
    std::vector<Mode> modes{Mode::blocking};
    if (cfg.following)
        modes.push_back(Mode::following);
    if (cfg.overlapped)
        modes.push_back(Mode::overlapped);
    const std::size_t total = modes.size() * cfg.gaps_us.size() * cfg.payload_bytes.size();
    std::size_t done = 0;
    for (const Mode mode : modes)
        for (const int bytes : cfg.payload_bytes)
            for (const double gap : cfg.gaps_us) {
                const Point p = measure(cfg, chain, work, rate, gap, bytes, size, cores, mode);
                ++done;
                if (rank == 0) {
                    points.push_back(point_json(p, size, cores));
                    if (!cfg.quiet)
                        std::fprintf(stderr,
                                     "exchange: %zu/%zu  %d ranks, %s, gap %6.0f us, %6d B: "
                                     "shift mean %.2f us, median %.2f us\n",
                                     done, total, size, mode_name(mode), gap, bytes,
                                     p.shift.avg * 1e6, p.shift.median * 1e6);
                }
            }
    double sink = work.sink(), total_sink = 0;
    MPI_Reduce(&sink, &total_sink, 1, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    if (rank == 0) {
        nlohmann::json report = report_header("exchange", topo);
        report["config"] = {{"gaps_us", cfg.gaps_us},
                            {"payload_bytes", cfg.payload_bytes},
                            {"seconds_per_point", cfg.seconds_per_point},
                            {"min_rounds", cfg.min_rounds},
                            {"max_rounds", cfg.max_rounds},
                            {"work_bytes", cfg.work_bytes},
                            {"following", cfg.following},
                            {"overlapped", cfg.overlapped}};
        report["ranks"] = size;
        report["cores"] = cores;
        report["oversubscribed"] = size > cores;
        report["work_elements_per_us"] = rate;
        report["work_checksum"] = total_sink; // keeps the work from being optimised away
        report["points"] = points;
        const std::size_t per_mode = cfg.gaps_us.size() * cfg.payload_bytes.size();
        for (std::size_t m = 0; m < modes.size(); ++m) {
            const std::string what = modes[m] == Mode::overlapped ? "overlapped (exposed part)"
                                     : modes[m] == Mode::following
                                         ? "following a " + std::to_string(lead_bytes) + " B shift"
                                         : "blocking";
            std::printf("exchange on %d ranks (%d cores), %s: mean / median shift cost, us\n", size,
                        cores, what.c_str());
            std::printf("%10s", modes[m] == Mode::overlapped ? "behind us" : "gap us");
            for (const int b : cfg.payload_bytes)
                std::printf("  %17d B", b);
            std::printf("\n");
            for (std::size_t g = 0; g < cfg.gaps_us.size(); ++g) {
                std::printf("%10.0f", cfg.gaps_us[g]);
                for (std::size_t b = 0; b < cfg.payload_bytes.size(); ++b) {
                    const auto &s = points[m * per_mode + b * cfg.gaps_us.size() + g]["shift"];
                    std::printf("  %8.2f / %8.2f", s["mean_s"].get<double>() * 1e6,
                                s["median_s"].get<double>() * 1e6);
                }
                std::printf("\n");
            }
        }
        JsonSink(cfg.json).write(report);
    }
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    return sphperf::mpi_program("exchange", argc, argv, run);
}
