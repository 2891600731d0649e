// MPI ping-pong over every rank pair, one pair at a time while the others wait (thesis 3.8.3):
// adaptive repetitions until the median round trip is known to +-5% (95% CI), a piecewise
// Hockney fit per pair, the thesis' two-point estimates, and a locality class per pair.
#include "mpi_program.hpp"
#include "sphperf/allocation.hpp"
#include "sphperf/cli.hpp"
#include "sphperf/model/hockney.hpp"
#include "sphperf/report.hpp"
#include "sphperf/stats.hpp"
#include "sphperf/topology.hpp"

#include <mpi.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <type_traits>
#include <vector>

namespace {

using namespace sphperf;
using model::MessageSample;

constexpr int tag_data = 1;
constexpr int tag_control = 2;
constexpr int tag_result = 3;
constexpr int warmup_round_trips = 5;
constexpr int chunk_samples = 10; // convergence is checked after each chunk of samples
constexpr std::size_t host_chars = 256;
constexpr std::size_t cpuset_chars = 256;

struct Config {
    std::int64_t min_bytes = 1;
    std::int64_t max_bytes = std::int64_t{16} << 20;
    int min_samples = 20;
    int max_samples = 1000;
    double max_seconds = 1.0;       // per message size
    double target_ci = 0.05;        // half-width of the median's 95% CI, relative
    int latency_round_trips = 1000; // thesis two-point estimate: 1 B x 1000
    int bandwidth_round_trips = 10; // ... and one large message x 10
    std::optional<std::filesystem::path> json;
    bool quiet = false;
};

struct SizeResult {
    double bytes = 0, median_s = 0, ci_lo_s = 0, ci_hi_s = 0, min_s = 0;
    double repetitions = 0; // round trips timed
    double samples = 0;     // batch means the median is taken over
    double batch = 0;       // round trips per sample
    double converged = 0;
};

struct PairResult {
    int i = 0, j = 0;
    std::vector<SizeResult> sizes;
    double two_point_alpha_s = 0, two_point_beta_s_per_byte = 0;
};

struct RankInfo {
    std::string host;
    std::string cpuset;
    int last_cpu = -1;
    bool bound = false; // process bound to a single core
};

// Waits at a barrier without spinning: with more ranks than cores, spinning idle ranks would
// steal the cores of the measured pair.
void quiet_barrier(MPI_Comm comm) {
    MPI_Request req;
    MPI_Ibarrier(comm, &req);
    int done = 0;
    for (;;) {
        MPI_Test(&req, &done, MPI_STATUS_IGNORE);
        if (done)
            return;
        usleep(200);
    }
}

std::vector<double> message_sizes(const Config &cfg) {
    std::vector<double> sizes;
    for (std::int64_t m = cfg.min_bytes; m <= cfg.max_bytes; m *= 2)
        sizes.push_back(static_cast<double>(m));
    return sizes;
}

// Each sample times a batch of round trips lasting >= this, so the timer's own cost (tens of ns
// on a VM) stays below 1% even for sub-microsecond latencies, as OSU and NetPIPE do.
constexpr double min_batch_seconds = 10e-6;
constexpr int max_batch = 4096;

void round_trips(std::vector<char> &buf, int bytes, int count, int peer, bool initiator) {
    for (int k = 0; k < count; ++k) {
        if (initiator) {
            MPI_Send(buf.data(), bytes, MPI_BYTE, peer, tag_data, MPI_COMM_WORLD);
            MPI_Recv(buf.data(), bytes, MPI_BYTE, peer, tag_data, MPI_COMM_WORLD,
                     MPI_STATUS_IGNORE);
        } else {
            MPI_Recv(buf.data(), bytes, MPI_BYTE, peer, tag_data, MPI_COMM_WORLD,
                     MPI_STATUS_IGNORE);
            MPI_Send(buf.data(), bytes, MPI_BYTE, peer, tag_data, MPI_COMM_WORLD);
        }
    }
}

// Initiator side of one message size; the partner mirrors it in serve_size.
SizeResult measure_size(const Config &cfg, std::vector<char> &buf, int bytes, int partner) {
    round_trips(buf, bytes, warmup_round_trips, partner, true);
    // Size the batch from a short probe, then tell the partner.
    const double t_probe = MPI_Wtime();
    round_trips(buf, bytes, warmup_round_trips, partner, true);
    const double rtt = (MPI_Wtime() - t_probe) / warmup_round_trips;
    int batch = static_cast<int>(std::ceil(min_batch_seconds / std::max(rtt, 1e-9)));
    batch = std::clamp(batch, 1, max_batch);
    MPI_Send(&batch, 1, MPI_INT, partner, tag_control, MPI_COMM_WORLD);

    std::vector<double> one_way;
    const double start = MPI_Wtime();
    int more = 1;
    bool converged = false;
    while (more) {
        for (int k = 0; k < chunk_samples; ++k) {
            const double t0 = MPI_Wtime();
            round_trips(buf, bytes, batch, partner, true);
            one_way.push_back((MPI_Wtime() - t0) / (2.0 * batch));
        }
        const double med = median(one_way);
        const Interval ci = median_ci95(one_way);
        const double half = 0.5 * (ci.hi - ci.lo);
        converged =
            static_cast<int>(one_way.size()) >= cfg.min_samples && half <= cfg.target_ci * med;
        const bool capped = static_cast<int>(one_way.size()) >= cfg.max_samples ||
                            MPI_Wtime() - start >= cfg.max_seconds;
        more = !(converged || capped);
        MPI_Send(&more, 1, MPI_INT, partner, tag_control, MPI_COMM_WORLD);
    }
    const Interval ci = median_ci95(one_way);
    const Summary s = summarize(one_way);
    const double n = static_cast<double>(one_way.size());
    return {static_cast<double>(bytes),
            s.median,
            ci.lo,
            ci.hi,
            s.min,
            n * batch,
            n,
            static_cast<double>(batch),
            converged ? 1.0 : 0.0};
}

void serve_size(std::vector<char> &buf, int bytes, int initiator) {
    round_trips(buf, bytes, 2 * warmup_round_trips, initiator, false);
    int batch = 1;
    MPI_Recv(&batch, 1, MPI_INT, initiator, tag_control, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    int more = 1;
    while (more) {
        round_trips(buf, bytes, chunk_samples * batch, initiator, false);
        MPI_Recv(&more, 1, MPI_INT, initiator, tag_control, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    }
}

// The thesis' estimate: time `count` round trips of `bytes`, divide by 2 x count.
double timed_round_trips(std::vector<char> &buf, int bytes, int count, int peer, bool initiator) {
    const double t0 = MPI_Wtime();
    round_trips(buf, bytes, count, peer, initiator);
    return (MPI_Wtime() - t0) / (2.0 * count);
}

// Runs the pair (i, j) on ranks i and j; returns the result on rank i.
PairResult run_pair(const Config &cfg, int rank, int i, int j, std::vector<char> &buf) {
    PairResult r{i, j, {}, 0, 0};
    const bool initiator = rank == i;
    const int peer = initiator ? j : i;
    for (double m : message_sizes(cfg)) {
        const int bytes = static_cast<int>(m);
        if (initiator)
            r.sizes.push_back(measure_size(cfg, buf, bytes, peer));
        else
            serve_size(buf, bytes, i);
    }
    const double latency = timed_round_trips(buf, 1, cfg.latency_round_trips, peer, initiator);
    const auto large = static_cast<int>(cfg.max_bytes);
    const double large_one_way =
        timed_round_trips(buf, large, cfg.bandwidth_round_trips, peer, initiator);
    r.two_point_alpha_s = latency;
    r.two_point_beta_s_per_byte = large_one_way / large;
    return r;
}

// Ships a pair result from rank i to rank 0: the two-point figures, then the per-size records as
// raw bytes (same binary on one node or a homogeneous cluster).
static_assert(std::is_trivially_copyable_v<SizeResult>);

void send_result(const PairResult &r) {
    const std::array<double, 2> two_point{r.two_point_alpha_s, r.two_point_beta_s_per_byte};
    MPI_Send(two_point.data(), 2, MPI_DOUBLE, 0, tag_result, MPI_COMM_WORLD);
    MPI_Send(r.sizes.data(), static_cast<int>(r.sizes.size() * sizeof(SizeResult)), MPI_BYTE, 0,
             tag_result, MPI_COMM_WORLD);
}

PairResult recv_result(int i, int j, std::size_t n_sizes) {
    std::array<double, 2> two_point{};
    MPI_Recv(two_point.data(), 2, MPI_DOUBLE, i, tag_result, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    PairResult r{i, j, std::vector<SizeResult>(n_sizes), two_point[0], two_point[1]};
    MPI_Recv(r.sizes.data(), static_cast<int>(n_sizes * sizeof(SizeResult)), MPI_BYTE, i,
             tag_result, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return r;
}

std::vector<RankInfo> gather_rank_info(const Topology &topo, int rank, int size) {
    std::array<char, host_chars> host{};
    std::array<char, cpuset_chars> cpus{};
    const std::string h = node_name(); // SLURMD_NODENAME: emulated nodes count as nodes
    const CpuSet binding = topo.this_process_binding();
    const std::string c = binding.to_list();
    std::copy_n(h.begin(), std::min(h.size(), host_chars - 1), host.begin());
    std::copy_n(c.begin(), std::min(c.size(), cpuset_chars - 1), cpus.begin());
    const int last = topo.last_cpu_of_this_thread();
    std::vector<char> hosts(rank == 0 ? host_chars * size : 0),
        sets(rank == 0 ? cpuset_chars * size : 0);
    std::vector<int> lasts(rank == 0 ? size : 0);
    MPI_Gather(host.data(), host_chars, MPI_CHAR, hosts.data(), host_chars, MPI_CHAR, 0,
               MPI_COMM_WORLD);
    MPI_Gather(cpus.data(), cpuset_chars, MPI_CHAR, sets.data(), cpuset_chars, MPI_CHAR, 0,
               MPI_COMM_WORLD);
    MPI_Gather(&last, 1, MPI_INT, lasts.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
    std::vector<RankInfo> info;
    for (int r = 0; rank == 0 && r < size; ++r)
        info.push_back({std::string(&hosts[r * host_chars]), std::string(&sets[r * cpuset_chars]),
                        lasts[static_cast<std::size_t>(r)], false});
    return info;
}

// Locality of two ranks: other node by host name, else by the PU each is bound to (or last ran
// on, when the process is not bound to one core).
Locality pair_locality(const Topology &topo, const RankInfo &a, const RankInfo &b) {
    if (a.host != b.host)
        return Locality::other_node;
    auto pu_of = [](const RankInfo &r) {
        int first = -1;
        if (std::sscanf(r.cpuset.c_str(), "%d", &first) == 1 && r.bound)
            return first;
        return r.last_cpu;
    };
    const int pa = pu_of(a), pb = pu_of(b);
    if (pa < 0 || pb < 0)
        return Locality::same_package; // unknown placement on one node: assume the usual case
    return topo.classify(pa, pb);
}

Config parse(int argc, char **argv) {
    Config cfg;
    cli::App app{"MPI ping-pong over every rank pair (one pair at a time): Hockney alpha/beta per "
                 "pair with a piecewise fit at the eager/rendezvous switch, two-point estimates, "
                 "and locality classes. Run under mpirun with >= 2 ranks (scripts/mpirun.sh)."};
    app.add_option("--min-bytes", cfg.min_bytes, "Smallest message (power of two)");
    app.add_option("--max-bytes", cfg.max_bytes, "Largest message (power of two)");
    app.add_option("--min-samples", cfg.min_samples,
                   "Timed samples per size before convergence is tested (each sample is a "
                   "batch of round trips lasting >= 10 us)");
    app.add_option("--max-samples", cfg.max_samples, "Timed samples per size at most");
    app.add_option("--max-seconds", cfg.max_seconds, "Time per message size at most");
    app.add_option("--target-ci", cfg.target_ci,
                   "Stop when the median's 95% CI half-width is below this fraction");
    app.add_option("--latency-round-trips", cfg.latency_round_trips,
                   "Round trips of 1 B for the two-point latency estimate");
    app.add_option("--bandwidth-round-trips", cfg.bandwidth_round_trips,
                   "Round trips of --max-bytes for the two-point bandwidth estimate");
    app.add_option("--json", cfg.json, "Write the JSON report to this file");
    app.add_flag("--quiet", cfg.quiet, "No progress lines on stderr");
    parse_cli(app, argc, argv);

    auto power_of_two = [](std::int64_t v) { return v > 0 && (v & (v - 1)) == 0; };
    if (!power_of_two(cfg.min_bytes))
        throw UsageError("--min-bytes " + std::to_string(cfg.min_bytes) +
                         " is not a positive power of two");
    if (!power_of_two(cfg.max_bytes) || cfg.max_bytes > (std::int64_t{1} << 30))
        throw UsageError("--max-bytes " + std::to_string(cfg.max_bytes) +
                         " is not a power of two in 1..1073741824");
    if (cfg.max_bytes < cfg.min_bytes)
        throw UsageError("--max-bytes " + std::to_string(cfg.max_bytes) + " is below --min-bytes " +
                         std::to_string(cfg.min_bytes));
    if (cfg.min_samples < chunk_samples)
        throw UsageError("--min-samples " + std::to_string(cfg.min_samples) + " is below " +
                         std::to_string(chunk_samples));
    if (cfg.max_samples < cfg.min_samples)
        throw UsageError("--max-samples " + std::to_string(cfg.max_samples) +
                         " is below --min-samples " + std::to_string(cfg.min_samples));
    if (!(cfg.max_seconds > 0))
        throw UsageError("--max-seconds " + std::to_string(cfg.max_seconds) + " is not positive");
    if (!(cfg.target_ci > 0 && cfg.target_ci < 1))
        throw UsageError("--target-ci " + std::to_string(cfg.target_ci) + " is outside (0, 1)");
    if (cfg.latency_round_trips < 1 || cfg.bandwidth_round_trips < 1)
        throw UsageError("round-trip counts must be >= 1");
    return cfg;
}

nlohmann::json fit_json(const model::LineFit &f) {
    return {{"alpha_s", f.alpha_s},
            {"beta_s_per_byte", f.beta_s_per_byte},
            {"r2", f.r2},
            {"max_rel_residual", f.max_rel_residual},
            {"first_bytes", f.first_bytes},
            {"last_bytes", f.last_bytes},
            {"points", f.points}};
}

nlohmann::json build_report(const Topology &topo, const Config &cfg,
                            const std::vector<RankInfo> &ranks,
                            const std::vector<PairResult> &pairs) {
    const int size = static_cast<int>(ranks.size());
    nlohmann::json report = report_header("pingpong", topo);
    report["ranks"] = size;
    report["config"] = {{"min_bytes", cfg.min_bytes},
                        {"max_bytes", cfg.max_bytes},
                        {"min_samples", cfg.min_samples},
                        {"max_samples", cfg.max_samples},
                        {"min_batch_s", min_batch_seconds},
                        {"max_seconds_per_size", cfg.max_seconds},
                        {"target_ci", cfg.target_ci},
                        {"latency_round_trips", cfg.latency_round_trips},
                        {"bandwidth_round_trips", cfg.bandwidth_round_trips}};
    for (int r = 0; r < size; ++r)
        report["rank_placement"].push_back({{"rank", r},
                                            {"node", ranks[r].host},
                                            {"cpuset", ranks[r].cpuset},
                                            {"bound_to_one_core", ranks[r].bound},
                                            {"last_cpu", ranks[r].last_cpu}});
    nlohmann::json alpha = nlohmann::json::array(), beta = nlohmann::json::array();
    for (int r = 0; r < size; ++r) {
        alpha.push_back(std::vector<nlohmann::json>(static_cast<std::size_t>(size)));
        beta.push_back(std::vector<nlohmann::json>(static_cast<std::size_t>(size)));
    }
    struct ClassStats {
        int pairs = 0;
        double alpha_sum = 0, alpha_max = 0, beta_sum = 0, beta_max = 0;
    };
    std::map<std::string, ClassStats> classes;
    for (const auto &p : pairs) {
        std::vector<MessageSample> samples;
        for (const auto &s : p.sizes)
            samples.push_back({s.bytes, s.median_s});
        const auto fit = model::fit_piecewise(samples);
        const auto loc = std::string(to_string(pair_locality(topo, ranks[p.i], ranks[p.j])));
        nlohmann::json j{{"ranks", {p.i, p.j}},
                         {"locality", loc},
                         {"alpha_s", fit.alpha_s()},
                         {"beta_s_per_byte", fit.beta_s_per_byte()},
                         {"bandwidth_GBps", 1e-9 / fit.beta_s_per_byte()},
                         {"r2", fit.r2},
                         {"max_rel_residual", fit.max_rel_residual},
                         {"breakpoint_bytes", fit.breakpoint_bytes},
                         {"single_line", fit_json(fit.single)},
                         {"two_point",
                          {{"alpha_s", p.two_point_alpha_s},
                           {"beta_s_per_byte", p.two_point_beta_s_per_byte},
                           {"latency_bytes", 1},
                           {"bandwidth_bytes", cfg.max_bytes}}}};
        for (const auto &piece : fit.pieces)
            j["pieces"].push_back(fit_json(piece));
        for (const auto &s : p.sizes)
            j["samples"].push_back({{"bytes", s.bytes},
                                    {"median_s", s.median_s},
                                    {"ci95_lo_s", s.ci_lo_s},
                                    {"ci95_hi_s", s.ci_hi_s},
                                    {"min_s", s.min_s},
                                    {"repetitions", static_cast<int>(s.repetitions)},
                                    {"samples", static_cast<int>(s.samples)},
                                    {"round_trips_per_sample", static_cast<int>(s.batch)},
                                    {"converged", s.converged > 0}});
        report["pairs"].push_back(j);
        alpha[p.i][p.j] = alpha[p.j][p.i] = fit.alpha_s();
        beta[p.i][p.j] = beta[p.j][p.i] = fit.beta_s_per_byte();
        auto &c = classes[loc];
        ++c.pairs;
        c.alpha_sum += fit.alpha_s();
        c.beta_sum += fit.beta_s_per_byte();
        c.alpha_max = std::max(c.alpha_max, fit.alpha_s());
        c.beta_max = std::max(c.beta_max, fit.beta_s_per_byte());
    }
    report["alpha_matrix_s"] = alpha;
    report["beta_matrix_s_per_byte"] = beta;
    for (const auto &[name, c] : classes)
        report["classes"][name] = {{"pairs", c.pairs},
                                   {"alpha_s_avg", c.alpha_sum / c.pairs},
                                   {"alpha_s_max", c.alpha_max},
                                   {"beta_s_per_byte_avg", c.beta_sum / c.pairs},
                                   {"beta_s_per_byte_max", c.beta_max}};
    return report;
}

void print_report(const nlohmann::json &report) {
    std::printf("ping-pong: %d ranks, %zu pairs\n", report["ranks"].get<int>(),
                report["pairs"].size());
    std::printf("%-7s %-13s %10s %10s %8s %11s %12s %12s\n", "pair", "locality", "alpha us",
                "1/beta GB/s", "R^2", "break B", "2pt alpha us", "2pt GB/s");
    for (const auto &p : report["pairs"])
        std::printf("%d-%-5d %-13s %10.3f %10.2f %8.4f %11.0f %12.3f %12.2f\n",
                    p["ranks"][0].get<int>(), p["ranks"][1].get<int>(),
                    p["locality"].get<std::string>().c_str(), p["alpha_s"].get<double>() * 1e6,
                    p["bandwidth_GBps"].get<double>(), p["r2"].get<double>(),
                    p["breakpoint_bytes"].get<double>(),
                    p["two_point"]["alpha_s"].get<double>() * 1e6,
                    1e-9 / p["two_point"]["beta_s_per_byte"].get<double>());
    const auto &first = report["pairs"][0];
    std::printf("\nsamples of pair %d-%d (one-way time = round trip / 2)\n%10s %12s %12s %8s "
                "%6s\n",
                first["ranks"][0].get<int>(), first["ranks"][1].get<int>(), "bytes", "median us",
                "MB/s", "samples", "batch");
    for (const auto &s : first["samples"])
        std::printf("%10.0f %12.3f %12.1f %8d %6d%s\n", s["bytes"].get<double>(),
                    s["median_s"].get<double>() * 1e6,
                    s["bytes"].get<double>() / s["median_s"].get<double>() * 1e-6,
                    s["samples"].get<int>(), s["round_trips_per_sample"].get<int>(),
                    s["converged"].get<bool>() ? "" : " (capped)");
}

int run(int argc, char **argv, int rank, int size) {
    const Topology topo;
    // Every rank parses the same arguments, so every rank reaches the same verdict.
    const Config cfg = parse(argc, argv);
    require_ranks("ping-pong", size);
    check_report_path_on_root(cfg.json, rank);

    std::vector<RankInfo> ranks = gather_rank_info(topo, rank, size);
    if (rank == 0)
        for (auto &r : ranks) {
            int first = -1, last = -1;
            // A single-core binding is "N" (one PU) or a range inside one core.
            r.bound = std::sscanf(r.cpuset.c_str(), "%d-%d", &first, &last) >= 1 &&
                      r.cpuset.find(',') == std::string::npos &&
                      (last < 0 || topo.classify(first, last) == Locality::same_core);
        }

    std::vector<char> buf(static_cast<std::size_t>(cfg.max_bytes), 'x');
    const std::size_t n_sizes = message_sizes(cfg).size();
    const int total = size * (size - 1) / 2;
    std::vector<PairResult> pairs;
    int done = 0;
    for (int i = 0; i < size; ++i)
        for (int j = i + 1; j < size; ++j) {
            quiet_barrier(MPI_COMM_WORLD);
            PairResult r;
            if (rank == i || rank == j)
                r = run_pair(cfg, rank, i, j, buf);
            if (rank == i && i != 0)
                send_result(r);
            if (rank == 0) {
                pairs.push_back(i == 0 ? r : recv_result(i, j, n_sizes));
                ++done;
                if (!cfg.quiet)
                    std::fprintf(stderr, "pingpong: pair %d/%d done (ranks %d-%d)\n", done, total,
                                 i, j);
            }
        }
    quiet_barrier(MPI_COMM_WORLD);

    if (rank == 0) {
        const nlohmann::json report = build_report(topo, cfg, ranks, pairs);
        print_report(report);
        JsonSink(cfg.json).write(report);
    }
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    return sphperf::mpi_program("pingpong", argc, argv, run);
}
