// STREAM: sustainable memory bandwidth per thread count and affinity (McCalpin's four kernels
// plus a non-temporal-store triad), with threads bound by hwloc and results validated.
#include "stream_kernels.hpp"
#include "stream_width.hpp"

#include "sphperf/allocation.hpp"
#include "sphperf/cli.hpp"
#include "sphperf/report.hpp"
#include "sphperf/stats.hpp"
#include "sphperf/timer.hpp"
#include "sphperf/topology.hpp"

#include <omp.h>
#include <sys/mman.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace {

using namespace sphperf;
namespace st = sphperf::stream;
using Real = double;

constexpr std::size_t cache_multiple = 4; // STREAM's rule: each array >= 4x all last-level caches
// Arrays start on a 2 MiB boundary so the kernel can back them with transparent huge pages.
constexpr std::size_t alignment_bytes = std::size_t{2} << 20;
constexpr int arrays_used = 3;

struct Config {
    std::int64_t size = 0; // elements per array; 0 = sized from the last-level cache
    int reps = 10;         // timed repetitions; one more runs first and is dropped
    std::vector<int> threads;
    std::vector<std::string> affinities{"compact", "scatter"};
    std::string huge_pages = "on"; // madvise(MADV_HUGEPAGE) on the arrays
    std::vector<int> vector_bits;  // empty: every width this CPU supports
    std::optional<std::filesystem::path> json;
    bool quiet = false;
};

// Default-initialised (untouched) aligned storage, so first touch happens in the bound threads.
struct AlignedDelete {
    void operator()(Real *p) const { ::operator delete[](p, std::align_val_t{alignment_bytes}); }
};
using Buffer = std::unique_ptr<Real[], AlignedDelete>;
Buffer allocate(std::size_t n) {
    return Buffer(new (std::align_val_t{alignment_bytes}) Real[n]);
}

// Faulting in 4 KiB pages dominated the stage on a VM whose hwloc reports a 1 GiB last-level
// cache (12 GiB of arrays, 181 s of the main job; perf put 45 % of one placement in the page
// faults); 2 MiB pages fault 512 times less often. Returns whether the kernel took the advice.
bool advise_huge_pages(const Buffer &b, std::size_t n) {
#ifdef MADV_HUGEPAGE
    return ::madvise(b.get(), n * sizeof(Real), MADV_HUGEPAGE) == 0;
#else
    (void)b;
    (void)n;
    return false;
#endif
}

// The system's transparent huge page mode (the bracketed word of the sysfs file), or "unknown".
std::string thp_mode() {
    std::ifstream in("/sys/kernel/mm/transparent_hugepage/enabled");
    std::string line;
    std::getline(in, line);
    const auto open = line.find('['), close = line.find(']');
    if (open == std::string::npos || close == std::string::npos || close < open)
        return "unknown";
    return line.substr(open + 1, close - open - 1);
}

struct Placement {
    int thread;
    std::string cpuset;
    int last_cpu;
};

struct ConfigResult {
    int vector_bits;
    int threads;
    Affinity affinity;
    std::array<std::vector<double>, st::kernels.size()> times; // seconds, dropped rep removed
    std::vector<double> nt_times;
    st::Validation validation, validation_nt;
    std::vector<Placement> placement;
};

// Runs `body(thread, range)` on `threads` OpenMP threads and returns the wall time of the region.
template <class Body> double timed_parallel(std::size_t n, int threads, Body &&body) {
    const double t0 = wall_seconds();
#pragma omp parallel num_threads(threads)
    {
        const int t = omp_get_thread_num();
        body(t, st::chunk(n, threads, t));
    }
    return wall_seconds() - t0;
}

// The three arrays of one placement (thread count and affinity), allocated and first-touched
// once by the bound threads and reused by every vector width: with arrays sized from a 300 MB
// last-level cache, faulting in 3.6 GB for each width took about a fifth of the stage.
class Arrays {
public:
    Arrays(const Topology &topo, std::size_t n, int threads, Affinity affinity, bool huge_pages)
        : n_(n), threads_(threads), a_(allocate(n)), b_(allocate(n)), c_(allocate(n)) {
        // Before the first touch, which decides the page size.
        advised_ = huge_pages && advise_huge_pages(a_, n) && advise_huge_pages(b_, n) &&
                   advise_huge_pages(c_, n);
        place(topo, threads, affinity);
    }

    // The same arrays for the next placement, written again by its own bound threads. Only
    // where pages cannot land on the wrong memory (one NUMA node): faulting the arrays in
    // again took about 45 s of 4 KiB pages a placement on this VM.
    void move_to(const Topology &topo, int threads, Affinity affinity) {
        threads_ = threads;
        used_ = false;
        place(topo, threads, affinity);
    }

    // STREAM's initial values again, by each thread on its own part, once a width has used
    // them (the first width finds them as the constructor left them).
    void reset() {
        if (!used_) {
            used_ = true;
            return;
        }
        timed_parallel(n_, threads_, [&](int, st::Range rg) { initialise(rg); });
    }

    // The reference's check, each thread summing its own part (a serial pass over 3.6 GB took
    // about a second per check).
    st::Validation validate(const std::array<Real, 3> &expected) const {
        std::vector<std::array<double, 3>> sums(static_cast<std::size_t>(threads_));
        timed_parallel(n_, threads_, [&](int t, st::Range rg) {
            const auto part = [&](const Buffer &x) {
                return std::span<const Real>(x.get() + rg.begin, rg.end - rg.begin);
            };
            sums[static_cast<std::size_t>(t)] =
                st::abs_error_sums<Real>(part(a_), part(b_), part(c_), expected);
        });
        std::array<double, 3> total{};
        for (const auto &s : sums)
            for (std::size_t k = 0; k < total.size(); ++k)
                total[k] += s[k];
        return st::validation_from_sums<Real>(total, n_, expected);
    }

    Real *a() { return a_.get(); }
    Real *b() { return b_.get(); }
    Real *c() { return c_.get(); }
    std::size_t size() const { return n_; }
    int threads() const { return threads_; }
    bool huge_pages_advised() const { return advised_; }

private:
    // Bind, then write each thread's own part of the arrays with STREAM's initial values (on
    // first touch the pages land near that core). The threads stay bound: OpenMP keeps its pool
    // for the later regions.
    void place(const Topology &topo, int threads, Affinity affinity) {
        const auto places = topo.placement(threads, affinity);
        int team = 0;
        std::atomic<int> bind_failures{0};
        timed_parallel(n_, threads, [&](int t, st::Range rg) {
            try { // an exception must not leave an OpenMP region
                topo.bind_this_thread(places[static_cast<std::size_t>(t)]);
            } catch (const std::exception &) {
                ++bind_failures;
            }
            if (t == 0)
                team = omp_get_num_threads();
            initialise(rg);
        });
        if (bind_failures > 0)
            throw std::runtime_error("hwloc could not bind " +
                                     std::to_string(bind_failures.load()) +
                                     " thread(s); is the process restricted to fewer cores?");
        if (team != threads)
            throw std::runtime_error("OpenMP gave " + std::to_string(team) +
                                     " threads, asked for " + std::to_string(threads));
    }

    // STREAM's initial values and its doubling of a, on one thread's part.
    void initialise(st::Range rg) {
        for (std::size_t j = rg.begin; j < rg.end; ++j) {
            a_[j] = st::Initial<Real>::a;
            b_[j] = st::Initial<Real>::b;
            c_[j] = st::Initial<Real>::c;
        }
        for (std::size_t j = rg.begin; j < rg.end; ++j)
            a_[j] = 2 * a_[j];
    }

    std::size_t n_;
    int threads_;
    Buffer a_, b_, c_;
    bool advised_ = false;
    bool used_ = false;
};

ConfigResult run_config(const Topology &topo, const st::KernelSet &ks, Arrays &arrays,
                        Affinity affinity, int reps) {
    const std::size_t n = arrays.size();
    const int threads = arrays.threads();
    ConfigResult r{ks.vector_bits, threads, affinity, {}, {}, {}, {}, {}};
    arrays.reset();
    Real *a = arrays.a(), *b = arrays.b(), *c = arrays.c();

    const Real s = st::Initial<Real>::scalar;
    for (int k = 0; k <= reps; ++k) {
        const std::array<double, 4> t{
            timed_parallel(
                n, threads,
                [&](int, st::Range rg) { ks.copy(&a[rg.begin], &c[rg.begin], rg.end - rg.begin); }),
            timed_parallel(n, threads,
                           [&](int, st::Range rg) {
                               ks.scale(&c[rg.begin], &b[rg.begin], s, rg.end - rg.begin);
                           }),
            timed_parallel(n, threads,
                           [&](int, st::Range rg) {
                               ks.add(&a[rg.begin], &b[rg.begin], &c[rg.begin], rg.end - rg.begin);
                           }),
            timed_parallel(n, threads, [&](int, st::Range rg) {
                ks.triad(&a[rg.begin], &b[rg.begin], &c[rg.begin], s, rg.end - rg.begin);
            })};
        if (k > 0) // the first repetition warms caches and page tables: dropped, as in STREAM
            for (std::size_t i = 0; i < t.size(); ++i)
                r.times[i].push_back(t[i]);
    }
    const auto expected = st::expected_values<Real>(reps + 1);
    r.validation = arrays.validate(expected);

    // Non-temporal triad on a cleared `a`, so a kernel that stored nothing cannot pass.
    timed_parallel(n, threads,
                   [&](int, st::Range rg) { std::fill(a + rg.begin, a + rg.end, Real{0}); });
    for (int k = 0; k <= reps; ++k) {
        const double t = timed_parallel(n, threads, [&](int, st::Range rg) {
            ks.triad_nt(&a[rg.begin], &b[rg.begin], &c[rg.begin], s, rg.end - rg.begin);
        });
        if (k > 0)
            r.nt_times.push_back(t);
    }
    r.validation_nt = arrays.validate({expected[1] + s * expected[2], expected[1], expected[2]});

    // Record where each thread is bound and last ran, after all the timed work.
    r.placement.resize(static_cast<std::size_t>(threads));
    timed_parallel(n, threads, [&](int t, st::Range) {
        r.placement[static_cast<std::size_t>(t)] = {t, topo.this_thread_binding().to_list(),
                                                    topo.last_cpu_of_this_thread()};
    });
    return r;
}

nlohmann::json kernel_json(std::span<const double> times, double bytes) {
    const Summary s = summarize(times);
    return {{"bytes_per_iteration", bytes},
            {"best_GBps", bytes / s.min * 1e-9},
            {"avg_GBps", bytes / s.avg * 1e-9},
            {"min_s", s.min},
            {"avg_s", s.avg},
            {"max_s", s.max},
            {"median_s", s.median}};
}

nlohmann::json validation_json(const st::Validation &v) {
    return {{"ok", v.ok},
            {"rel_error", {{"a", v.rel_error[0]}, {"b", v.rel_error[1]}, {"c", v.rel_error[2]}}},
            {"epsilon", st::validation_epsilon}};
}

Config parse(int argc, char **argv, const Topology &topo) {
    Config cfg;
    cli::App app{"STREAM memory bandwidth (copy, scale, add, triad, non-temporal triad) over a "
                 "thread sweep with compact and scatter affinity bound by hwloc."};
    app.add_option("--size", cfg.size,
                   "Elements per array (default: 4x the last-level cache, STREAM's rule)");
    app.add_option("--reps", cfg.reps, "Timed repetitions per kernel (one extra is dropped)");
    app.add_option("--threads", cfg.threads, "Thread counts to sweep (default 1..cores)")
        ->delimiter(',');
    app.add_option("--affinity", cfg.affinities, "Affinities to sweep: compact, scatter")
        ->delimiter(',');
    app.add_option("--vector-bits", cfg.vector_bits,
                   "Kernel vector widths to sweep: 128, 256, 512 (default: all the CPU has)")
        ->delimiter(',');
    app.add_option("--json", cfg.json, "Write the JSON report to this file");
    app.add_option("--huge-pages", cfg.huge_pages,
                   "Ask for transparent huge pages on the arrays (madvise): on, off. Faulting "
                   "them in 4 KiB pages can take longer than the timed kernels")
        ->check(cli::IsMember({"on", "off"}))
        ->capture_default_str();
    app.add_flag("--quiet", cfg.quiet, "No progress lines on stderr");
    parse_cli(app, argc, argv);

    if (app.count("--size") && cfg.size <= 0)
        throw UsageError("--size " + std::to_string(cfg.size) +
                         " is not a positive number of elements per array");
    if (cfg.reps < 2)
        throw UsageError("--reps " + std::to_string(cfg.reps) + " is too few, expected >= 2");
    if (cfg.threads.empty())
        for (int t = 1; t <= usable_cores(topo); ++t)
            cfg.threads.push_back(t);
    check_thread_counts(cfg.threads, topo, "stream");
    for (const auto &a : cfg.affinities)
        parse_affinity(a);
    if (cfg.affinities.empty())
        throw UsageError("--affinity needs at least one of compact, scatter");
    return cfg;
}

// The requested widths, each checked against what this CPU and build support.
std::vector<st::KernelSet> select_kernel_sets(const std::vector<int> &bits) {
    const auto available = st::available_kernel_sets();
    if (bits.empty())
        return available;
    std::vector<st::KernelSet> out;
    for (int b : bits) {
        const auto it = std::find_if(available.begin(), available.end(),
                                     [b](const st::KernelSet &k) { return k.vector_bits == b; });
        if (it == available.end()) {
            std::string have;
            for (const auto &k : available)
                have += (have.empty() ? "" : ", ") + std::to_string(k.vector_bits);
            throw UsageError("--vector-bits " + std::to_string(b) +
                             " is not available on this CPU, expected one of " + have);
        }
        out.push_back(*it);
    }
    return out;
}

std::size_t array_elements(const Config &cfg, const Topology &topo) {
    std::size_t n = 0;
    if (cfg.size > 0) {
        n = static_cast<std::size_t>(cfg.size);
    } else {
        const std::uint64_t llc = topo.last_level_cache_bytes();
        constexpr std::size_t fallback_elements = 10'000'000; // STREAM's default
        n = llc > 0 ? cache_multiple * llc / sizeof(Real) : fallback_elements;
    }
    const double need = static_cast<double>(arrays_used * sizeof(Real)) * static_cast<double>(n);
    const auto mem = static_cast<double>(topo.memory_bytes());
    if (mem > 0 && need > 0.8 * mem)
        throw UsageError("--size " + std::to_string(n) + " needs " +
                         std::to_string(need / (1 << 20)) + " MiB, more than 80% of the node's " +
                         std::to_string(mem / (1 << 20)) + " MiB");
    return n;
}

void print_table(const std::vector<ConfigResult> &results, std::size_t n, int reps,
                 std::uint64_t llc) {
    std::printf("STREAM: %zu doubles per array (%.1f MiB), %d timed repetitions (+1 dropped), "
                "last-level cache %.1f MiB\n",
                n, static_cast<double>(n * sizeof(Real)) / (1 << 20), reps,
                static_cast<double>(llc) / (1 << 20));
    std::printf("%4s %7s %-8s %-8s %10s %10s %11s %11s %11s\n", "bits", "threads", "affinity",
                "kernel", "best GB/s", "avg GB/s", "min s", "avg s", "max s");
    auto row = [](const ConfigResult &r, std::string_view name, std::span<const double> t,
                  double bytes) {
        const Summary s = summarize(t);
        std::printf("%4d %7d %-8s %-8s %10.2f %10.2f %11.6f %11.6f %11.6f\n", r.vector_bits,
                    r.threads, std::string(to_string(r.affinity)).c_str(),
                    std::string(name).c_str(), bytes / s.min * 1e-9, bytes / s.avg * 1e-9, s.min,
                    s.avg, s.max);
    };
    for (const auto &r : results) {
        for (std::size_t k = 0; k < st::kernels.size(); ++k)
            row(r, st::kernels[k].name, r.times[k], st::bytes_moved<Real>(st::kernels[k], n));
        row(r, "triad_nt", r.nt_times,
            st::bytes_moved<Real>(st::kernels[static_cast<int>(st::Kernel::triad)], n));
    }
}

int run(int argc, char **argv) {
    // Only the cores this process may use (a Slurm allocation, taskset): threads placed
    // outside them would escape the allocation and measure someone else's cores.
    const Topology topo(TopologyScope::binding);
    const Config cfg = parse(argc, argv, topo);
    const JsonSink sink(cfg.json);
    const std::size_t n = array_elements(cfg, topo);
    omp_set_dynamic(0);

    const std::vector<st::KernelSet> kernel_sets = select_kernel_sets(cfg.vector_bits);
    // An affinity that puts the threads on the PUs an earlier one used measures the same thing
    // (on 2 cores compact and scatter coincide at every thread count): it runs once and the
    // report names the other as the same placement, instead of spending the time twice (with
    // arrays sized from a 480 MB last-level cache, 18 s per configuration here).
    struct Planned {
        int threads;
        std::string affinity;
    };
    std::vector<Planned> plan;
    nlohmann::json same_placement = nlohmann::json::array();
    for (int threads : cfg.threads) {
        std::vector<std::pair<std::string, std::vector<std::string>>> seen;
        for (const auto &aff : cfg.affinities) {
            std::vector<std::string> pus;
            for (const auto &set : topo.placement(threads, parse_affinity(aff)))
                pus.push_back(set.to_list());
            const auto it = std::find_if(seen.begin(), seen.end(),
                                         [&](const auto &s) { return s.second == pus; });
            if (it != seen.end()) {
                same_placement.push_back(
                    {{"threads", threads}, {"affinity", aff}, {"same_as", it->first}});
                continue;
            }
            seen.emplace_back(aff, std::move(pus));
            plan.push_back({threads, aff});
        }
    }
    std::vector<ConfigResult> results;
    const std::size_t total = plan.size() * kernel_sets.size();
    const bool want_huge = cfg.huge_pages == "on";
    bool all_advised = want_huge;
    const bool reuse_arrays = topo.numa_nodes() <= 1;
    std::optional<Arrays> arrays;
    for (const auto &[threads, aff] : plan) {
        if (arrays && reuse_arrays) {
            arrays->move_to(topo, threads, parse_affinity(aff));
        } else {
            arrays.reset(); // free one placement's arrays before the next one's
            arrays.emplace(topo, n, threads, parse_affinity(aff), want_huge);
        }
        all_advised = all_advised && arrays->huge_pages_advised();
        for (const auto &ks : kernel_sets) {
            results.push_back(run_config(topo, ks, *arrays, parse_affinity(aff), cfg.reps));
            if (!cfg.quiet)
                std::fprintf(stderr, "stream: %zu/%zu done (threads=%d affinity=%s bits=%d)\n",
                             results.size(), total, threads, aff.c_str(), ks.vector_bits);
        }
    }

    nlohmann::json report = report_header("stream", topo);
    report["allocation"] = allocation_summary(topo);
    report["array_elements"] = n;
    report["element_bytes"] = sizeof(Real);
    report["array_bytes"] = n * sizeof(Real);
    // What was asked and what the kernel said; with THP "never" the advice is taken and ignored.
    report["huge_pages"] = {
        {"requested", want_huge}, {"advised", all_advised}, {"system_thp_mode", thp_mode()}};
    report["arrays_reused_across_placements"] = reuse_arrays; // one NUMA node: no re-fault
    report["repetitions_timed"] = cfg.reps;
    report["repetitions_dropped"] = 1;
    for (const auto &ks : kernel_sets)
        report["vector_bits_measured"].push_back(ks.vector_bits);
    const auto &triad_spec = st::kernels[static_cast<int>(st::Kernel::triad)];
    double best_triad = 0, best_nt = 0;
    bool all_valid = true;
    for (const auto &r : results) {
        nlohmann::json j{{"threads", r.threads},
                         {"affinity", to_string(r.affinity)},
                         {"vector_bits", r.vector_bits}};
        for (std::size_t k = 0; k < st::kernels.size(); ++k)
            j["kernels"][st::kernels[k].name] =
                kernel_json(r.times[k], st::bytes_moved<Real>(st::kernels[k], n));
        j["triad_nt"] = kernel_json(r.nt_times, st::bytes_moved<Real>(triad_spec, n));
        j["validation"] = validation_json(r.validation);
        j["validation_nt"] = validation_json(r.validation_nt);
        for (const auto &p : r.placement)
            j["placement"].push_back(
                {{"thread", p.thread}, {"cpuset", p.cpuset}, {"last_cpu", p.last_cpu}});
        best_triad = std::max(best_triad, j["kernels"]["triad"]["best_GBps"].get<double>());
        best_nt = std::max(best_nt, j["triad_nt"]["best_GBps"].get<double>());
        all_valid = all_valid && r.validation.ok && r.validation_nt.ok;
        report["results"].push_back(j);
    }
    report["best_triad_GBps"] = best_triad;
    report["best_triad_nt_GBps"] = best_nt;
    report["valid"] = all_valid;
    report["same_placement"] = same_placement;

    print_table(results, n, cfg.reps, topo.last_level_cache_bytes());
    for (const auto &d : same_placement)
        std::printf("%s at %d thread(s): the same PUs as %s, measured once\n",
                    d["affinity"].get<std::string>().c_str(), d["threads"].get<int>(),
                    d["same_as"].get<std::string>().c_str());
    if (!all_valid) {
        std::fprintf(stderr,
                     "stream: validation FAILED: results differ from the scalar replay "
                     "by more than %g; no report written\n",
                     st::validation_epsilon);
        return exit_failure;
    }
    sink.write(report);
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    return sphperf::guarded_main("stream", [&] { return run(argc, argv); });
}
