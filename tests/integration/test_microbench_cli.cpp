// The benchmark executables as a user runs them: tiny sizes, real reports, bad input.
#include "run.hpp"

#include <cstdlib>
#include <map>

#include <gtest/gtest.h>

using namespace sphperf::testing;
namespace fs = std::filesystem;

namespace {
const std::string tiny_stream = " --size 200000 --reps 2 --quiet";

const std::string tiny_dgemm = " --sizes 64,96 --reps 2 --probe-reps 1 --quiet";
const std::string tiny_pingpong = " --max-bytes 65536 --max-samples 40 --max-seconds 0.2 "
                                  "--latency-round-trips 20 --bandwidth-round-trips 2 --quiet";
} // namespace

TEST(StreamCli, TinyRunWritesACompleteReport) {
    const auto dir = scratch("stream");
    const auto r =
        run(bin("stream") + tiny_stream + " --threads 1 --json " + (dir / "s.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = load(dir / "s.json");
    expect_envelope(j, "stream");
    expect_keys(j, {"/results/0/threads", "/results/0/affinity", "/results/0/triad_nt/best_GBps",
                    "/results/0/placement/0/cpuset", "/best_triad_GBps", "/valid"});
    for (const char *k : {"copy", "scale", "add", "triad"})
        for (const char *f : {"best_GBps", "avg_GBps", "min_s", "avg_s", "max_s"})
            EXPECT_TRUE(j["results"][0]["kernels"][k].contains(f)) << k << "." << f;
    EXPECT_TRUE(j["valid"].get<bool>());
    EXPECT_EQ(j["array_elements"].get<int>(), 200000);
    // By default every vector width the CPU supports is measured, 128 bits at least.
    const auto widths = j["vector_bits_measured"];
    ASSERT_GE(widths.size(), 1u);
    EXPECT_EQ(widths[0], 128);
    // x 2 affinities, 1 thread count, less an affinity that places the threads as the other
    // (measured once: on 2 cores compact and scatter coincide)
    ASSERT_LE(j["same_placement"].size(), 1u);
    EXPECT_EQ(j["results"].size(), (2 - j["same_placement"].size()) * widths.size());
    expect_figures_sane(j);
    EXPECT_NE(r.out.find("triad"), std::string::npos); // human table on stdout
    // Huge pages are asked for by default; the report says so and what the system's mode is.
    EXPECT_TRUE(j["huge_pages"]["requested"].get<bool>());
    EXPECT_FALSE(j["huge_pages"]["system_thp_mode"].get<std::string>().empty());
    EXPECT_TRUE(j["arrays_reused_across_placements"].is_boolean());
}

// Two placements on the same arrays (one NUMA node) or on new ones: either way every result
// validates; with --huge-pages off nothing is advised; a bad value exits 2 with no report.
TEST(StreamCli, HugePagesOffAndTwoPlacementsValidate) {
    const auto dir = scratch("stream_pages");
    const auto out = dir / "s.json";
    const auto r = run(bin("stream") + tiny_stream +
                       " --threads 1,2 --affinity compact --vector-bits 128 --huge-pages off "
                       "--json " +
                       out.string());
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = load(out);
    EXPECT_FALSE(j["huge_pages"]["requested"].get<bool>());
    EXPECT_FALSE(j["huge_pages"]["advised"].get<bool>());
    ASSERT_EQ(j["results"].size(), 2u);
    for (const auto &res : j["results"]) {
        EXPECT_TRUE(res["validation"]["ok"].get<bool>()) << res["threads"];
        EXPECT_TRUE(res["validation_nt"]["ok"].get<bool>()) << res["threads"];
    }
    EXPECT_EQ(j["results"][1]["threads"], 2);
    fs::remove(out);
    const auto bad =
        run(bin("stream") + tiny_stream + " --huge-pages maybe --json " + out.string());
    EXPECT_EQ(bad.code, 2);
    EXPECT_NE(bad.err.find("maybe"), std::string::npos) << bad.err;
    EXPECT_FALSE(fs::exists(out));
}

TEST(StreamCli, SweepsRequestedThreadsAndAffinities) {
    const auto dir = scratch("stream_sweep");
    const auto r = run(bin("stream") + tiny_stream + " --threads 1,2 --affinity compact,scatter" +
                       " --vector-bits 128 --json " + (dir / "s.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = load(dir / "s.json");
    // Every (threads, affinity) asked for is measured, or named as placed like one measured at
    // the same thread count, whose placement is then listed; no two measured ones coincide.
    std::map<std::pair<int, std::string>, std::vector<std::string>> measured;
    for (const auto &res : j["results"]) {
        EXPECT_EQ(res["vector_bits"], 128);
        const int threads = res["threads"].get<int>();
        ASSERT_EQ(res["placement"].size(), static_cast<std::size_t>(threads));
        std::vector<std::string> pus;
        for (const auto &p : res["placement"])
            pus.push_back(p["cpuset"].get<std::string>());
        measured[{threads, res["affinity"].get<std::string>()}] = pus;
    }
    for (const auto &d : j["same_placement"]) {
        const int threads = d["threads"].get<int>();
        EXPECT_EQ(measured.count({threads, d["affinity"].get<std::string>()}), 0u);
        EXPECT_EQ(measured.count({threads, d["same_as"].get<std::string>()}), 1u);
    }
    EXPECT_EQ(measured.size() + j["same_placement"].size(), 4u);
    for (const auto &[a, pa] : measured)
        for (const auto &[b, pb] : measured)
            if (a < b && a.first == b.first) {
                EXPECT_NE(pa, pb) << a.second << " and " << b.second << " placed alike";
            }
    // Each thread is bound to exactly one processing unit, and they differ.
    const auto &two = measured.at({2, "compact"});
    EXPECT_NE(two[0], two[1]);
}

// A benchmark bound to one core (taskset, as Slurm's task/affinity binds a task) or told by
// SLURM_CPUS_PER_TASK measures that many cores by default, places its threads inside its
// binding, says where it ran, and refuses thread counts beyond its binding.
TEST(Allocation, BenchmarksStayInsideTheirAllocation) {
    if (run("nproc").out.find_first_not_of("01\n") == std::string::npos)
        GTEST_SKIP() << "needs two or more cores";
    const auto dir = scratch("allocation");
    const auto s1 = dir / "s_core1.json";
    auto r = run("env -u SLURM_CPUS_PER_TASK taskset -c 1 " + bin("stream") + tiny_stream +
                 " --affinity compact --vector-bits 128 --json " + s1.string());
    ASSERT_EQ(r.code, 0) << r.err;
    auto j = load(s1);
    ASSERT_EQ(j["results"].size(), 1u); // 1 thread x 1 affinity x 1 width
    EXPECT_EQ(j["results"][0]["threads"], 1);
    EXPECT_EQ(j["results"][0]["placement"][0]["cpuset"], "1");
    EXPECT_EQ(j["allocation"]["bound_pus"], "1");
    EXPECT_EQ(j["allocation"]["usable_cores"], 1);
    EXPECT_TRUE(j["allocation"]["slurm_cpus_per_task"].is_null());
    r = run("env SLURM_CPUS_PER_TASK=1 " + bin("stream") + tiny_stream +
            " --affinity compact --vector-bits 128 --json " + (dir / "s_slurm.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    j = load(dir / "s_slurm.json");
    ASSERT_EQ(j["results"].size(), 1u);
    EXPECT_EQ(j["allocation"]["slurm_cpus_per_task"], 1);
    // More threads than Slurm gave the task: measured as asked, with a warning.
    r = run("env SLURM_CPUS_PER_TASK=1 " + bin("stream") + tiny_stream +
            " --threads 2 --affinity compact --vector-bits 128 --json " +
            (dir / "s_over.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("stream: warning: --threads 2 exceeds SLURM_CPUS_PER_TASK=1"),
              std::string::npos)
        << r.err;
    // More threads than the cores it is bound to: refused, naming them.
    r = run("taskset -c 1 " + bin("stream") + tiny_stream + " --threads 2 --json " +
            (dir / "s_bad.json").string());
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("--threads 2 is outside 1..1 (the processing units this process may "
                         "use: 1)"),
              std::string::npos)
        << r.err;
    EXPECT_FALSE(fs::exists(dir / "s_bad.json"));
    // DGEMM: 1 thread by default and a one-core peak probe.
    r = run("env -u SLURM_CPUS_PER_TASK taskset -c 1 " + bin("dgemm") + tiny_dgemm + " --json " +
            (dir / "d.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    j = load(dir / "d.json");
    for (const auto &res : j["results"])
        EXPECT_EQ(res["threads"], 1);
    EXPECT_EQ(j["peak_probe"]["threads"], 1);
    EXPECT_EQ(j["allocation"]["bound_pus"], "1");
}

TEST(DgemmCli, TinyRunWritesACompleteReport) {
    const auto dir = scratch("dgemm");
    const auto r =
        run(bin("dgemm") + tiny_dgemm + " --threads 1 --json " + (dir / "d.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = load(dir / "d.json");
    expect_envelope(j, "dgemm");
    expect_keys(j, {"/corename", "/results/0/n", "/results/0/threads", "/results/0/gflops",
                    "/results/0/avg_gflops", "/results/0/fraction_of_peak",
                    "/peak_probe/per_core_gflops", "/peak_probe/all_cores_gflops"});
    EXPECT_EQ(j["results"].size(), 2u);
    EXPECT_TRUE(j["results"][1]["check"]["ok"].get<bool>());
    EXPECT_EQ(j["results"][0]["timed_runs"], 2);
    expect_figures_sane(j);
}

// A time budget per size: with a budget no run can meet (1 ns), every size stops after the
// 2 runs it always times, whatever --reps asks; without one, all --reps are timed.
TEST(DgemmCli, TimeBudgetStopsAfterTwoRuns) {
    const auto dir = scratch("dgemm_budget");
    for (const std::string budget : {"1e-9", "0"}) {
        const auto out = dir / ("d" + budget + ".json");
        const auto r = run(bin("dgemm") + " --sizes 64 --reps 6 --no-probe --quiet --threads 1" +
                           " --max-seconds " + budget + " --json " + out.string());
        ASSERT_EQ(r.code, 0) << r.err;
        const auto j = load(out);
        EXPECT_EQ(j["results"][0]["timed_runs"], budget == "0" ? 6 : 2) << budget;
        EXPECT_EQ(j["repetitions_timed"], 6);
    }
}

TEST(PingpongCli, TwoAndThreeRanks) {
    for (int ranks : {2, 3}) {
        const auto dir = scratch("pingpong" + std::to_string(ranks));
        const auto r = run(mpirun(ranks) + bin("pingpong") + tiny_pingpong + " --json " +
                           (dir / "p.json").string());
        ASSERT_EQ(r.code, 0) << r.err;
        const auto j = load(dir / "p.json");
        expect_envelope(j, "pingpong");
        const std::size_t pairs = static_cast<std::size_t>(ranks * (ranks - 1) / 2);
        ASSERT_EQ(j["pairs"].size(), pairs);
        expect_keys(j, {"/pairs/0/ranks", "/pairs/0/locality", "/pairs/0/alpha_s",
                        "/pairs/0/beta_s_per_byte", "/pairs/0/r2", "/pairs/0/breakpoint_bytes",
                        "/pairs/0/pieces/0/alpha_s", "/pairs/0/pieces/0/beta_s_per_byte",
                        "/pairs/0/pieces/0/r2", "/pairs/0/pieces/0/max_rel_residual",
                        "/pairs/0/two_point/alpha_s", "/pairs/0/two_point/beta_s_per_byte",
                        "/pairs/0/samples/0/bytes", "/pairs/0/samples/0/median_s",
                        "/pairs/0/samples/0/repetitions", "/alpha_matrix_s",
                        "/beta_matrix_s_per_byte", "/classes"});
        EXPECT_EQ(j["alpha_matrix_s"].size(), static_cast<std::size_t>(ranks));
        EXPECT_EQ(j["pairs"][pairs - 1]["ranks"], nlohmann::json({ranks - 2, ranks - 1}));
        EXPECT_EQ(j["pairs"][0]["samples"].size(), 17u); // 1 B .. 64 KiB
        expect_figures_sane(j);
    }
}

const std::string tiny_exchange =
    " --gaps-us 0,200 --payload-bytes 64,1024 --seconds-per-point 0.01 --min-rounds 5 --quiet";

// The app's shift as a benchmark: every (payload, gap) point, mean beside median, at 2 and 3
// ranks (3 is above this machine's cores: the round overhead is reported); 1 rank is refused.
// At 2 ranks also following (a shift right after another, as the app's ghosts after its
// migration), at 3 overlapped (sph --overlap, the work behind the transfers as their gap): a
// second set of points each.
TEST(ExchangeCli, OneTwoAndThreeRanks) {
    for (int ranks : {1, 2, 3}) {
        const auto dir = scratch("exchange" + std::to_string(ranks));
        const auto out = dir / "e.json";
        const bool overlapped = ranks == 3;
        const bool following = ranks == 2;
        const auto r = run(mpirun(ranks) + bin("exchange") + tiny_exchange +
                           (overlapped ? " --overlapped" : "") + (following ? " --following" : "") +
                           " --json " + out.string());
        if (ranks == 1) {
            EXPECT_EQ(r.code, 2);
            EXPECT_NE(r.err.find("at least 2 MPI ranks"), std::string::npos) << r.err;
            EXPECT_FALSE(fs::exists(out));
            continue;
        }
        ASSERT_EQ(r.code, 0) << r.err;
        const auto j = load(out);
        expect_envelope(j, "exchange");
        EXPECT_EQ(j["ranks"].get<int>(), ranks);
        ASSERT_EQ(j["points"].size(), 8u);
        EXPECT_EQ(j["config"]["overlapped"].get<bool>(), overlapped);
        EXPECT_EQ(j["config"]["following"].get<bool>(), following);
        for (std::size_t i = 0; i < j["points"].size(); ++i) {
            EXPECT_EQ(j["points"][i]["overlapped"].get<bool>(), overlapped && i >= 4) << i;
            EXPECT_EQ(j["points"][i]["follows_shift"].get<bool>(), following && i >= 4) << i;
        }
        // Each point's work is 200 us (or none) at the elements per microsecond measured
        // first: counted, not timed, so that a loaded machine cannot fail this test.
        const double per_us = j["work_elements_per_us"].get<double>();
        EXPECT_GT(per_us, 0);
        for (std::size_t i = 0; i < j["points"].size(); ++i) {
            const auto &pt = j["points"][i];
            EXPECT_EQ(pt["work_elements"].get<double>(),
                      std::llround(pt["gap_work_us"].get<double>() * per_us))
                << i;
            // A blocking or following gap runs from the end of the shift before to the next
            // transfer, so it holds the work (and the shift before, following) whole.
            if (!pt["overlapped"].get<bool>())
                EXPECT_GE(pt["gap_s_mean"].get<double>(), pt["work_s_mean"].get<double>()) << i;
        }
        if (following) {
            EXPECT_NE(r.out.find("following a 64 B shift"), std::string::npos) << r.out;
            EXPECT_EQ(j["points"][5]["gap_work_us"].get<double>(), 200);
            EXPECT_GT(j["points"][5]["work_elements"].get<double>(), 0);
        }
        if (overlapped) {
            // The overlapped point with 200 us of work behind its transfers says so; its gap
            // is that work (what the app knows when it completes the transfers).
            EXPECT_EQ(j["points"][5]["gap_work_us"].get<double>(), 200);
            EXPECT_GT(j["points"][5]["work_elements"].get<double>(), 0);
            EXPECT_EQ(j["points"][4]["work_elements"].get<double>(), 0);
            EXPECT_EQ(j["points"][5]["gap_s_mean"].get<double>(),
                      j["points"][5]["work_s_mean"].get<double>());
            EXPECT_NE(r.out.find("overlapped (exposed part)"), std::string::npos) << r.out;
        }
        expect_keys(j, {"/points/0/gap_s_mean", "/points/0/payload_bytes", "/points/0/shift/mean_s",
                        "/points/0/shift/median_s", "/points/0/shift/p90_s",
                        "/points/0/round_s_mean", "/work_elements_per_us"});
        for (const auto &pt : j["points"]) {
            const auto &sh = pt["shift"];
            EXPECT_LE(sh["min_s"].get<double>(), sh["median_s"].get<double>());
            EXPECT_LE(sh["median_s"].get<double>(), sh["max_s"].get<double>());
            EXPECT_GE(sh["mean_s"].get<double>(), sh["min_s"].get<double>());
            // Every rank's every round is a sample.
            EXPECT_EQ(sh["samples"].get<double>(), ranks * pt["rounds"].get<double>());
        }
        EXPECT_EQ(j["points"][0]["gap_work_us"].get<double>(), 0);
        EXPECT_EQ(j["points"][0]["work_elements"].get<double>(), 0);
        EXPECT_TRUE(j["points"][1]["round_overhead"].is_number());
        expect_figures_sane(j);
    }
    const auto bad = run(mpirun(2) + bin("exchange") + " --gaps-us 10,nan --json /tmp/x.json");
    EXPECT_EQ(bad.code, 2);
    EXPECT_EQ(bad.err_lines(), 1) << bad.err;
}

// The launcher raises Open MPI's shared-memory eager limit (sph/README.md, "Overlap") unless
// the user set it, and the report says which limit its figures ran under.
TEST(Launcher, SetsTheEagerLimitUnlessTheUserDid) {
    const auto dir = scratch("launcher");
    const auto out = dir / "e.json";
    const char *own = std::getenv("OMPI_MCA_btl_vader_eager_limit");
    for (const std::string &limit : {std::string(), std::string("8192")}) {
        const auto r = run((limit.empty() ? "" : "OMPI_MCA_btl_vader_eager_limit=" + limit + " ") +
                           mpirun(2) + bin("exchange") + tiny_exchange + " --json " + out.string());
        ASSERT_EQ(r.code, 0) << r.err;
        const auto j = load(out);
        const std::string expected = !limit.empty() ? limit : own ? own : "262144";
        EXPECT_EQ(j.at("mpi_mca").value("btl_vader_eager_limit", ""), expected);
    }
}

TEST(MachineProfileCli, MergesTheThreeReports) {
    const auto dir = scratch("profile");
    const auto s = dir / "s.json", d = dir / "d.json", p = dir / "p.json", m = dir / "m.json";
    ASSERT_EQ(run(bin("stream") + tiny_stream + " --threads 1 --json " + s.string()).code, 0);
    ASSERT_EQ(run(bin("dgemm") + tiny_dgemm + " --threads 1 --json " + d.string()).code, 0);
    ASSERT_EQ(run(mpirun(2) + bin("pingpong") + tiny_pingpong + " --json " + p.string()).code, 0);
    const auto e = dir / "e.json";
    ASSERT_EQ(run(mpirun(2) + bin("exchange") + tiny_exchange + " --json " + e.string()).code, 0);
    const auto r =
        run(bin("machine-profile") + " --stream " + s.string() + " --dgemm " + d.string() +
            " --pingpong " + p.string() + " --exchange " + e.string() + " --out " + m.string());
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.out.find("halo exchange, 2 ranks"), std::string::npos) << r.out;
    const auto j = load(m);
    expect_envelope(j, "machine");
    expect_keys(j, {"/peak_gflops", "/dgemm_gflops", "/stream_triad_GBps", "/ridge_flop_per_byte",
                    "/stream/results", "/dgemm/results", "/pingpong/pairs", "/alpha_matrix_s",
                    "/comm_classes", "/exchange/0/points/0/shift/mean_s", "/exchange/0/ranks"});
    EXPECT_NEAR(j["ridge_flop_per_byte"].get<double>(),
                j["peak_gflops"].get<double>() / j["stream_triad_GBps"].get<double>(), 1e-12);
    // Swapped inputs are refused with a clear error and no output.
    fs::remove(m);
    const auto bad = run(bin("machine-profile") + " --stream " + d.string() + " --dgemm " +
                         d.string() + " --pingpong " + p.string() + " --out " + m.string());
    EXPECT_EQ(bad.code, 2);
    EXPECT_EQ(bad.err_lines(), 1) << bad.err;
    EXPECT_FALSE(fs::exists(m));
}

// Bad input: exit code 2, one line naming the problem, and no report file.
struct BadInput {
    std::string name, command, expect_in_message;
};

void PrintTo(const BadInput &b, std::ostream *os) {
    *os << b.name;
}

class BadInputTest : public ::testing::TestWithParam<BadInput> {};

TEST_P(BadInputTest, ExitsTwoWithOneLineAndNoFile) {
    const auto dir = scratch("bad_" + GetParam().name);
    const auto out = dir / "report.json";
    std::string cmd = GetParam().command;
    const auto pos = cmd.find("@OUT@");
    if (pos != std::string::npos)
        cmd.replace(pos, 5, out.string());
    const auto r = run(cmd);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1) << r.err;
    EXPECT_NE(r.err.find(GetParam().expect_in_message), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out));
    EXPECT_TRUE(fs::is_empty(dir)) << "left a file behind";
}

INSTANTIATE_TEST_SUITE_P(
    Microbench, BadInputTest,
    ::testing::Values(
        BadInput{"stream_negative_size", bin("stream") + " --size -5 --json @OUT@", "-5"},
        BadInput{"stream_zero_size", bin("stream") + " --size 0 --json @OUT@", "--size 0"},
        BadInput{"stream_affinity", bin("stream") + " --size 1000 --affinity diagonal --json @OUT@",
                 "diagonal"},
        BadInput{"stream_threads", bin("stream") + " --size 1000 --threads 0 --json @OUT@",
                 "--threads 0"},
        BadInput{"stream_vector_bits", bin("stream") + " --size 1000 --vector-bits 96 --json @OUT@",
                 "--vector-bits 96"},
        BadInput{"stream_unwritable", bin("stream") + " --size 1000 --json /nonexistent/dir/s.json",
                 "/nonexistent/dir/s.json"},
        BadInput{"stream_unknown_option", bin("stream") + " --sise 1000 --json @OUT@", "sise"},
        BadInput{"dgemm_negative_size", bin("dgemm") + " --sizes -3 --json @OUT@", "-3"},
        BadInput{"dgemm_huge", bin("dgemm") + " --sizes 10000000 --json @OUT@", "10000000"},
        BadInput{"dgemm_negative_budget", bin("dgemm") + " --max-seconds -1 --json @OUT@", "-1"},
        BadInput{"dgemm_unwritable", bin("dgemm") + " --sizes 8 --json /nonexistent/dir/d.json",
                 "/nonexistent/dir/d.json"},
        BadInput{"pingpong_one_rank", bin("pingpong") + " --json @OUT@", "at least 2 MPI ranks"},
        BadInput{"pingpong_one_rank_launcher", mpirun(1) + bin("pingpong") + " --json @OUT@",
                 "at least 2 MPI ranks"},
        BadInput{"pingpong_unwritable",
                 mpirun(2) + bin("pingpong") + " --json /nonexistent/dir/p.json",
                 "/nonexistent/dir/p.json"},
        BadInput{"pingpong_bad_size",
                 mpirun(2) + bin("pingpong") + " --max-bytes 1000 --json @OUT@", "power of two"},
        BadInput{"profile_missing_input",
                 bin("machine-profile") +
                     " --stream /nonexistent/s.json --dgemm /nonexistent/d.json "
                     "--pingpong /nonexistent/p.json --out @OUT@",
                 "/nonexistent/s.json"}),
    [](const auto &info) { return info.param.name; });

// The malformed-report corpus (tests/data/malformed_reports.json): each case damages one key of a
// real tiny report; machine-profile must exit 2 with one line naming the file and the key, and
// write nothing.
TEST(MachineProfileCli, RefusesEveryMalformedReportOfTheCorpus) {
    const auto dir = scratch("malformed");
    std::map<std::string, fs::path> good{{"stream", dir / "s.json"},
                                         {"dgemm", dir / "d.json"},
                                         {"pingpong", dir / "p.json"},
                                         {"exchange", dir / "e.json"}};
    ASSERT_EQ(
        run(bin("stream") + tiny_stream + " --threads 1 --json " + good["stream"].string()).code,
        0);
    ASSERT_EQ(run(bin("dgemm") + tiny_dgemm + " --threads 1 --json " + good["dgemm"].string()).code,
              0);
    ASSERT_EQ(
        run(mpirun(2) + bin("pingpong") + tiny_pingpong + " --json " + good["pingpong"].string())
            .code,
        0);
    ASSERT_EQ(
        run(mpirun(2) + bin("exchange") + tiny_exchange + " --json " + good["exchange"].string())
            .code,
        0);
    const auto corpus = load(fs::path(SPHPERF_TEST_DATA_DIR) / "malformed_reports.json");
    ASSERT_GE(corpus["cases"].size(), 20u);
    const auto out = dir / "machine.json";
    for (const auto &c : corpus["cases"]) {
        const std::string name = c["name"], kind = c["report"];
        auto j = load(good.at(kind));
        const nlohmann::json::json_pointer ptr(c["pointer"].get<std::string>());
        if (c.value("remove", false))
            j.at(ptr.parent_pointer()).erase(ptr.back());
        else
            j[ptr] = c["value"];
        const auto bad = dir / (name + ".json");
        std::ofstream(bad) << j.dump();
        auto path = good;
        path[kind] = bad;
        const auto r =
            run(bin("machine-profile") + " --stream " + path["stream"].string() + " --dgemm " +
                path["dgemm"].string() + " --pingpong " + path["pingpong"].string() +
                " --exchange " + path["exchange"].string() + " --out " + out.string());
        EXPECT_EQ(r.code, 2) << name << ": " << r.err;
        EXPECT_EQ(r.err_lines(), 1) << name << ": " << r.err;
        EXPECT_NE(r.err.find(bad.string()), std::string::npos) << name << ": " << r.err;
        EXPECT_NE(r.err.find(c["expect"].get<std::string>()), std::string::npos)
            << name << ": " << r.err;
        EXPECT_FALSE(fs::exists(out)) << name;
        fs::remove(out);
    }
}

TEST(Help, EveryExecutableHasHelp) {
    for (const char *exe : {"stream", "dgemm", "pingpong", "machine-profile"}) {
        const auto r = run(bin(exe) + " --help");
        EXPECT_EQ(r.code, 0) << exe;
        EXPECT_NE(r.out.find("Usage"), std::string::npos) << exe;
        EXPECT_TRUE(r.err.empty()) << exe << ": " << r.err;
    }
}
