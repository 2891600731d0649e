// DGEMM: cblas_dgemm GFLOP/s over a size and thread sweep, checked against a naive product,
// beside an FMA peak probe that gives the attainable compute ceiling of this build and node.
#include "gemm_check.hpp"
#include "peak_probe.hpp"

#include "sphperf/allocation.hpp"
#include "sphperf/cli.hpp"
#include "sphperf/report.hpp"
#include "sphperf/stats.hpp"
#include "sphperf/timer.hpp"
#include "sphperf/topology.hpp"

#include <cblas.h>
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

namespace {

using namespace sphperf;

constexpr double memory_fraction = 0.5; // matrices may use at most half the node's memory
constexpr std::size_t spot_samples = 64;
constexpr double probe_min_seconds = 0.1;

struct Config {
    std::vector<std::int64_t> sizes;
    std::vector<int> threads;
    int reps = 10;
    double max_seconds = 0; // per size and thread count; 0: no budget
    int probe_reps = 5;
    bool no_probe = false;
    std::optional<std::filesystem::path> json;
    bool quiet = false;
};

struct GemmResult {
    std::size_t n;
    int threads;
    int blas_threads;
    int timed_runs;
    Summary seconds;
    gemm::SpotCheck check;
};

double matrix_bytes(std::int64_t n) {
    return 3.0 * 8.0 * static_cast<double>(n) * static_cast<double>(n);
}

// `reps` timed runs after a warm-up, or fewer (at least 2) once they have taken `max_seconds`.
GemmResult run_gemm(std::size_t n, int threads, int reps, double max_seconds) {
    openblas_set_num_threads(threads);
    std::vector<double> a(n * n), b(n * n), c(n * n, 0.0);
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<double> dist(-1.0, 1.0);
    for (auto &x : a)
        x = dist(rng);
    for (auto &x : b)
        x = dist(rng);
    const auto nn = static_cast<blasint>(n);
    constexpr double alpha = 1.0, beta = 0.0; // C = alpha A B + beta C with beta 0: 2 n^3 flops
    auto call = [&] {
        cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, nn, nn, nn, alpha, a.data(), nn,
                    b.data(), nn, beta, c.data(), nn);
    };
    call(); // warm-up: thread pool start, page faults
    std::vector<double> t;
    double spent = 0;
    for (int r = 0; r < reps; ++r) {
        if (max_seconds > 0 && r >= 2 && spent >= max_seconds)
            break;
        const double t0 = wall_seconds();
        call();
        t.push_back(wall_seconds() - t0);
        spent += t.back();
    }
    return {n,
            threads,
            openblas_get_num_threads(),
            static_cast<int>(t.size()),
            summarize(t),
            gemm::spot_check(a, b, c, n, n, n, spot_samples, 7)};
}

struct ProbeResult {
    double per_core_gflops = 0;
    double all_cores_gflops = 0;
    int threads = 0;
    std::int64_t iterations = 0;
};

// Best of `reps` runs of the FMA chains on `places.size()` bound threads, in GFLOP/s.
double probe_gflops(const Topology &topo, const std::vector<CpuSet> &places,
                    std::int64_t iterations, int reps) {
    const int threads = static_cast<int>(places.size());
    double best = 0;
    std::atomic<int> bind_failures{0};
    volatile double sink = 0;
    for (int r = 0; r < reps; ++r) {
        double t0 = 0, t1 = 0, checksum = 0;
#pragma omp parallel num_threads(threads) reduction(+ : checksum)
        {
            try {
                topo.bind_this_thread(places[static_cast<std::size_t>(omp_get_thread_num())]);
            } catch (const std::exception &) {
                ++bind_failures;
            }
#pragma omp barrier
#pragma omp master
            t0 = wall_seconds();
            checksum += probe::fma_chains(iterations, 1.0 + omp_get_thread_num());
#pragma omp barrier
#pragma omp master
            t1 = wall_seconds();
        }
        sink = sink + checksum;
        best = std::max(best, threads * probe::flops(iterations) / (t1 - t0) * 1e-9);
    }
    if (bind_failures > 0)
        throw std::runtime_error("hwloc could not bind the peak-probe threads");
    return best;
}

ProbeResult run_probe(const Topology &topo, int reps) {
    ProbeResult p;
    const auto one = topo.placement(1, Affinity::compact);
    // Calibrate so one run lasts >= probe_min_seconds: short runs measure the clock, not the FPU.
    std::int64_t iterations = 1 << 20;
    for (;;) {
        const double t0 = wall_seconds();
        volatile double s = probe::fma_chains(iterations, 1.0);
        (void)s;
        if (wall_seconds() - t0 >= probe_min_seconds)
            break;
        iterations *= 2;
    }
    p.iterations = iterations;
    p.per_core_gflops = probe_gflops(topo, one, iterations, reps);
    p.threads = usable_cores(topo);
    p.all_cores_gflops =
        probe_gflops(topo, topo.placement(p.threads, Affinity::scatter), iterations, reps);
    return p;
}

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char ch) { return std::tolower(ch); });
    return s;
}

// OpenBLAS 0.3.21 does not know recent AMD cores and falls back to its AVX2 (Haswell/Zen)
// kernels even when AVX-512 is there; name the core type that would use it.
std::optional<std::string> better_coretype(const std::string &corename) {
    static const std::vector<std::string> avx512_cores{"skylakex", "cooperlake", "sapphirerapids"};
    const bool cpu_has_avx512 = __builtin_cpu_supports("avx512f") &&
                                __builtin_cpu_supports("avx512dq") &&
                                __builtin_cpu_supports("avx512vl");
    if (!cpu_has_avx512)
        return std::nullopt;
    if (std::find(avx512_cores.begin(), avx512_cores.end(), lower(corename)) != avx512_cores.end())
        return std::nullopt;
    return "SkylakeX";
}

Config parse(int argc, char **argv, const Topology &topo) {
    Config cfg;
    cli::App app{"DGEMM (cblas_dgemm from OpenBLAS) GFLOP/s over matrix sizes and thread counts, "
                 "with an FMA peak probe giving the attainable compute ceiling."};
    app.add_option("--sizes", cfg.sizes,
                   "Square matrix sizes (default 1000,2000,4000 as memory allows)")
        ->delimiter(',');
    app.add_option("--threads", cfg.threads, "BLAS thread counts (default 1 and all cores)")
        ->delimiter(',');
    app.add_option("--reps", cfg.reps, "Timed runs per size (after one warm-up)");
    app.add_option("--max-seconds", cfg.max_seconds,
                   "Per size and thread count, stop timing once the runs took this long (at "
                   "least 2 runs; 0: always --reps)")
        ->check(FiniteNonNegative);
    app.add_option("--probe-reps", cfg.probe_reps, "Runs of the peak probe (best is kept)");
    app.add_flag("--no-probe", cfg.no_probe, "Skip the FMA peak probe");
    app.add_option("--json", cfg.json, "Write the JSON report to this file");
    app.add_flag("--quiet", cfg.quiet, "No progress lines on stderr");
    parse_cli(app, argc, argv);

    const double mem = static_cast<double>(topo.memory_bytes());
    if (cfg.sizes.empty()) {
        for (std::int64_t n : {1000, 2000, 4000})
            if (matrix_bytes(n) <= memory_fraction * mem)
                cfg.sizes.push_back(n);
    }
    for (auto n : cfg.sizes) {
        if (n <= 0)
            throw UsageError("--sizes " + std::to_string(n) + " is not a positive matrix size");
        if (matrix_bytes(n) > memory_fraction * mem)
            throw UsageError("--sizes " + std::to_string(n) + " needs " +
                             std::to_string(matrix_bytes(n) / (1 << 20)) +
                             " MiB for three matrices, more than half of this node's memory");
    }
    if (cfg.threads.empty()) {
        cfg.threads.push_back(1);
        if (usable_cores(topo) > 1)
            cfg.threads.push_back(usable_cores(topo));
    }
    check_thread_counts(cfg.threads, topo, "dgemm");
    if (cfg.reps < 1)
        throw UsageError("--reps " + std::to_string(cfg.reps) + " is too few, expected >= 1");
    if (cfg.probe_reps < 1)
        throw UsageError("--probe-reps " + std::to_string(cfg.probe_reps) +
                         " is too few, expected >= 1");
    return cfg;
}

int run(int argc, char **argv) {
    // Only the cores this process may use (a Slurm allocation, taskset): threads placed
    // outside them would escape the allocation and measure someone else's cores.
    const Topology topo(TopologyScope::binding);
    const Config cfg = parse(argc, argv, topo);
    const JsonSink sink(cfg.json);
    omp_set_dynamic(0);

    const std::string corename = openblas_get_corename();
    const char *env_coretype = std::getenv("OPENBLAS_CORETYPE");

    ProbeResult probe;
    if (!cfg.no_probe) {
        probe = run_probe(topo, cfg.probe_reps);
        if (!cfg.quiet)
            std::fprintf(stderr, "dgemm: peak probe %.1f GFLOP/s per core, %.1f on %d cores\n",
                         probe.per_core_gflops, probe.all_cores_gflops, probe.threads);
    }
    // The ceiling for t threads: the probe per core times t, capped by the all-core figure.
    auto ceiling = [&](int t) {
        return std::min(probe.per_core_gflops * t, probe.all_cores_gflops);
    };

    std::vector<GemmResult> results;
    const std::size_t total = cfg.sizes.size() * cfg.threads.size();
    for (int t : cfg.threads)
        for (auto n : cfg.sizes) {
            results.push_back(run_gemm(static_cast<std::size_t>(n), t, cfg.reps, cfg.max_seconds));
            if (!cfg.quiet)
                std::fprintf(stderr, "dgemm: %zu/%zu done (n=%lld threads=%d)\n", results.size(),
                             total, static_cast<long long>(n), t);
        }

    nlohmann::json report = report_header("dgemm", topo);
    report["allocation"] = allocation_summary(topo);
    report["corename"] = corename;
    report["openblas_coretype_env"] =
        env_coretype ? nlohmann::json(env_coretype) : nlohmann::json();
    report["repetitions_timed"] = cfg.reps;
    report["max_seconds_per_size"] = cfg.max_seconds;
    const auto advice = better_coretype(corename);
    report["suggested_coretype"] = advice ? nlohmann::json(*advice) : nlohmann::json();
    if (advice)
        report["coretype_advice"] =
            "OpenBLAS chose its '" + corename +
            "' kernels (AVX2) on a CPU with AVX-512. Run with OPENBLAS_CORETYPE=" + *advice +
            " to use its AVX-512 kernels, and compare fraction_of_peak between the two runs.";
    if (!cfg.no_probe)
        report["peak_probe"] = {{"per_core_gflops", probe.per_core_gflops},
                                {"all_cores_gflops", probe.all_cores_gflops},
                                {"threads", probe.threads},
                                {"vector_bits", probe::vector_bits},
                                {"isa", probe::isa},
                                {"chains", probe::chains},
                                {"iterations", probe.iterations}};
    bool all_ok = true;
    double best = 0;
    for (const auto &r : results) {
        const double flops = 2.0 * std::pow(static_cast<double>(r.n), 3);
        nlohmann::json j{{"n", r.n},
                         {"threads", r.threads},
                         {"blas_threads", r.blas_threads},
                         {"timed_runs", r.timed_runs},
                         {"flops_per_call", flops},
                         {"gflops", flops / r.seconds.min * 1e-9},
                         {"avg_gflops", flops / r.seconds.avg * 1e-9},
                         {"min_s", r.seconds.min},
                         {"avg_s", r.seconds.avg},
                         {"max_s", r.seconds.max},
                         {"check",
                          {{"ok", r.check.ok},
                           {"samples", r.check.checked},
                           {"worst_error_to_bound", r.check.worst_ratio}}}};
        if (!cfg.no_probe)
            j["fraction_of_peak"] = j["gflops"].get<double>() / ceiling(r.threads);
        best = std::max(best, j["gflops"].get<double>());
        all_ok = all_ok && r.check.ok;
        report["results"].push_back(j);
    }
    report["best_gflops"] = best;

    char budget[64] = "";
    if (cfg.max_seconds > 0)
        std::snprintf(budget, sizeof budget, ", fewer (at least 2) past %g s", cfg.max_seconds);
    std::printf("DGEMM: OpenBLAS core type %s%s, %d timed runs per size%s\n", corename.c_str(),
                env_coretype ? " (set by OPENBLAS_CORETYPE)" : "", cfg.reps, budget);
    if (!cfg.no_probe)
        std::printf("peak probe (%s, %d-bit FMA x %d chains): %.1f GFLOP/s per core, %.1f GFLOP/s "
                    "on %d cores\n",
                    std::string(probe::isa).c_str(), probe::vector_bits, probe::chains,
                    probe.per_core_gflops, probe.all_cores_gflops, probe.threads);
    std::printf("%6s %7s %5s %10s %10s %10s %9s %6s\n", "n", "threads", "runs", "best GF/s",
                "avg GF/s", "min s", "of peak", "check");
    for (const auto &j : report["results"])
        std::printf("%6zu %7d %5d %10.2f %10.2f %10.4f %8.1f%% %6s\n", j["n"].get<std::size_t>(),
                    j["threads"].get<int>(), j["timed_runs"].get<int>(), j["gflops"].get<double>(),
                    j["avg_gflops"].get<double>(), j["min_s"].get<double>(),
                    j.contains("fraction_of_peak") ? 100 * j["fraction_of_peak"].get<double>()
                                                   : 0.0,
                    j["check"]["ok"].get<bool>() ? "ok" : "FAIL");
    if (advice)
        std::printf("note: %s\n", report["coretype_advice"].get<std::string>().c_str());

    if (!all_ok) {
        std::fprintf(stderr, "dgemm: spot check FAILED: cblas_dgemm disagrees with the naive "
                             "product; no report written\n");
        return exit_failure;
    }
    sink.write(report);
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    return sphperf::guarded_main("dgemm", [&] { return run(argc, argv); });
}
