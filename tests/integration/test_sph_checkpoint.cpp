// Checkpoint and restart as a user runs them: a run stopped and continued ends exactly where an
// uninterrupted one ends (at the same rank count, and at another one: every grid sums in id
// order or in an order set by the particles alone), a rank killed with SIGKILL leaves a
// checkpoint to restart from, and a truncated, corrupt or mismatched checkpoint is refused with one
// line, overwriting nothing.
#include "run.hpp"
#include "sphperf/sph/checkpoint.hpp"
#include "sphperf/sph/config.hpp"
#include "state.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>

using namespace sphperf::testing;
namespace fs = std::filesystem;
namespace sph = sphperf::sph;

namespace {
const std::string base_args = "--quiet --interval 100 --threads 1 ";

// The tests' defaults (half scale; 300 steps for a restart) unless the case gives its own.
std::string with_defaults(const std::string &args) {
    std::string out = args;
    if (out.find("--scale") == std::string::npos)
        out += " --scale 0.5";
    if (out.find("--steps") == std::string::npos)
        out += " --steps 300";
    return out;
}

// The counters of every interval and rank, and the physics series.
void expect_same_record(const nlohmann::json &a, const nlohmann::json &b, bool same_ranks) {
    ASSERT_EQ(a["intervals"].size(), b["intervals"].size());
    EXPECT_EQ(a["physics"]["front_x"], b["physics"]["front_x"]);
    EXPECT_EQ(a["physics"]["time_s"], b["physics"]["time_s"]);
    if (!same_ranks)
        return; // other counters are per rank; sums over ranks reduce in another order
    // Balanced slabs: the same re-cuts at the same steps, moving the same particles.
    const auto &ra = a["decomposition"]["rebalances"], &rb = b["decomposition"]["rebalances"];
    ASSERT_EQ(ra.size(), rb.size());
    for (std::size_t k = 0; k < ra.size(); ++k)
        for (const char *key : {"step", "cuts", "moved_particles", "imbalance_after"})
            EXPECT_EQ(ra[k][key], rb[k][key]) << "rebalance " << k << " " << key;
    EXPECT_EQ(a["physics"]["kinetic_energy"], b["physics"]["kinetic_energy"]);
    for (std::size_t k = 0; k < a["intervals"].size(); ++k) {
        const auto &x = a["intervals"][k], &y = b["intervals"][k];
        EXPECT_EQ(x["columns"], y["columns"]) << "interval " << k;
        for (const char *key : {"column_interactions", "column_descents"})
            EXPECT_EQ(x.value(key, nlohmann::json()), y.value(key, nlohmann::json()))
                << "interval " << k << " " << key;
        for (std::size_t r = 0; r < x["ranks"].size(); ++r)
            for (const char *key : {"field", "pairs", "interactions", "descents", "cell_moves",
                                    "exported", "ghost", "migrated", "virtual"})
                EXPECT_EQ(x["ranks"][r][key], y["ranks"][r][key])
                    << "interval " << k << " rank " << r << " " << key;
    }
}

Run sph_run(int ranks, const std::string &args) {
    return run(mpirun(ranks) + bin("sph") + " " + base_args + with_defaults(args));
}
} // namespace

// Stopped at step 200 and continued to 400, at the same rank count (list and table grids keep
// their stored-list order too) and, for the sorted grid, at another one.
constexpr const char *BalancedTable = "table --decomposition balanced --rebalance-every 50";
struct Resume {
    std::string name, grid;
    int ranks_before, ranks_after;
};
void PrintTo(const Resume &r, std::ostream *os) {
    *os << r.name;
}
class SphRestartTest : public ::testing::TestWithParam<Resume> {};

TEST_P(SphRestartTest, ContinuedRunEndsIdenticalToAnUninterruptedOne) {
    const Resume &c = GetParam();
    const auto dir = scratch("ck_" + c.name);
    const std::string grid = "--grid " + c.grid + " ";
    auto r = sph_run(c.ranks_after, grid + "--steps 400 --checkpoint " + (dir / "full").string() +
                                        " --report " + (dir / "full.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    r = sph_run(c.ranks_before, grid + "--steps 200 --checkpoint " + (dir / "part").string());
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(sph::read_manifest(dir / "part").step, 200);
    r = sph_run(c.ranks_after, grid + "--steps 400 --restart " + (dir / "part").string() +
                                   " --checkpoint " + (dir / "part").string() + " --report " +
                                   (dir / "part.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    const auto full = load(dir / "full.json"), part = load(dir / "part.json");
    EXPECT_EQ(part["restart"]["from_step"], 200);
    EXPECT_EQ(sph::read_manifest(dir / "part").step, 400);
    EXPECT_FALSE(fs::exists(dir / "part" / sph::step_dir_name(200))) << "old checkpoint kept";
    expect_same_particles(dir / "full", dir / "part");
    expect_same_record(full, part, c.ranks_before == c.ranks_after);
}

INSTANTIATE_TEST_SUITE_P(Sph, SphRestartTest,
                         ::testing::Values(Resume{"table_1", "table", 1, 1},
                                           Resume{"table_2", "table", 2, 2},
                                           Resume{"table_2_to_3", "table", 2, 3},
                                           Resume{"list_3", "list", 3, 3},
                                           Resume{"sorted_3_to_2", "sorted", 3, 2},
                                           Resume{"sorted_1_to_3", "sorted", 1, 3},
                                           // Balanced slabs: the cuts come back with the
                                           // particles (same ranks) or are cut afresh.
                                           Resume{"balanced_3", BalancedTable, 3, 3},
                                           Resume{"balanced_3_to_2", BalancedTable, 3, 2}),
                         [](const auto &info) { return info.param.name; });

// One rank of three is killed (SIGKILL) mid-run: the job ends, the last complete checkpoint is
// intact, and the restart from it ends exactly where an uninterrupted run does.
TEST(SphRestart, KilledRankRestartsFromTheLastCompleteCheckpoint) {
    const auto dir = scratch("ck_kill");
    const auto ck = dir / "ck", full = dir / "full";
    const std::string args = "--grid table --steps 900 ";
    auto r = sph_run(3, args + "--checkpoint " + full.string() + " --report " +
                            (dir / "full.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    // Background job; wait for a checkpoint past step 300, kill the last rank found, and report
    // the job's exit code.
    const auto script = dir / "kill.sh";
    std::ofstream(script) << "( " << mpirun(3) << bin("sph") << " " << base_args
                          << with_defaults(args) << " --checkpoint " << ck.string() << " ) >"
                          << (dir / "killed.log").string() << " 2>&1 &\n"
                          << "job=$!\n"
                          << "for i in $(seq 1200); do\n"
                          << "  s=$(sed -n 's/^  \"step\": \\([0-9]*\\),*$/\\1/p' "
                          << (ck / "manifest.json").string() << " 2>/dev/null)\n"
                          << "  [ \"${s:-0}\" -ge 300 ] && break; sleep 0.025\n"
                          << "done\n"
                          << "echo \"checkpoint $s\"\n"
                          << "for p in $(pgrep -x sph); do\n"
                          << "  tr '\\0' ' ' </proc/$p/cmdline | grep -q '" << ck.string()
                          << "' && victim=$p\n"
                          << "done\n"
                          << "kill -9 $victim\n"
                          << "wait $job\n"
                          << "echo \"exit $?\"\n";
    r = run("bash " + script.string());
    ASSERT_NE(r.out.find("checkpoint "), std::string::npos) << r.out << r.err;
    EXPECT_EQ(r.out.find("exit 0"), std::string::npos) << "the killed job exited 0: " << r.out;
    const std::int64_t step = sph::read_manifest(ck).step;
    EXPECT_GE(step, 300);
    EXPECT_LT(step, 900) << "the job finished before the kill";
    r = sph_run(3, args + "--restart " + ck.string() + " --checkpoint " + ck.string() +
                       " --report " + (dir / "restarted.json").string());
    ASSERT_EQ(r.code, 0) << r.err;
    expect_same_particles(full, ck);
    expect_same_record(load(dir / "full.json"), load(dir / "restarted.json"), true);
}

// A checkpoint that cannot be trusted, or one of another run or code, is refused: exit 2, one
// line naming the file and the mismatch, no report, and not a byte of the checkpoint changed.
struct Broken {
    std::string name, args, expect;
    std::function<void(const fs::path &)> damage;
};
void PrintTo(const Broken &b, std::ostream *os) {
    *os << b.name;
}
class SphBadCheckpointTest : public ::testing::TestWithParam<Broken> {};

namespace {
std::map<std::string, std::string> contents(const fs::path &dir) {
    std::map<std::string, std::string> out;
    for (const auto &e : fs::recursive_directory_iterator(dir))
        if (e.is_regular_file())
            out[e.path().string()] = slurp(e.path());
    return out;
}
void rewrite(const fs::path &p, const std::function<void(std::string &)> &edit) {
    std::string s = slurp(p);
    edit(s);
    std::ofstream(p, std::ios::binary | std::ios::trunc) << s;
}
fs::path rank0(const fs::path &ck) {
    return ck / sph::read_manifest(ck).files[0].name;
}
} // namespace

TEST_P(SphBadCheckpointTest, ExitsTwoNamingTheFileAndTheMismatch) {
    const Broken &b = GetParam();
    const auto dir = scratch("ck_bad_" + b.name);
    const auto ck = dir / "ck";
    // One good checkpoint (1 rank, step 100), copied for every case.
    static const fs::path pristine = [] {
        const auto d = scratch("ck_pristine") / "ck";
        const auto r = sph_run(1, "--steps 100 --checkpoint " + d.string());
        EXPECT_EQ(r.code, 0) << r.err;
        return d;
    }();
    fs::copy(pristine, ck, fs::copy_options::recursive);
    b.damage(ck);
    sphperf::testing::Run r;
    const auto before = contents(dir);
    r = sph_run(1, "--restart " + ck.string() + " --checkpoint " + ck.string() + " --report " +
                       (dir / "r.json").string() + " " + b.args);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1) << r.err;
    EXPECT_NE(r.err.find(b.expect), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir / "r.json"));
    EXPECT_EQ(contents(dir), before) << "the refused restart changed the checkpoint";
}

INSTANTIATE_TEST_SUITE_P(
    Sph, SphBadCheckpointTest,
    ::testing::Values(
        Broken{
            "truncated", "", "bytes, the manifest says",
            [](const fs::path &ck) { fs::resize_file(rank0(ck), fs::file_size(rank0(ck)) / 2); }},
        Broken{"corrupt", "", "(corrupt)",
               [](const fs::path &ck) {
                   rewrite(rank0(ck), [](std::string &s) { s[s.size() / 2] ^= 0x10; });
               }},
        Broken{"other_setup", "--setup still", "setup dambreak in the checkpoint, still",
               [](const fs::path &) {}},
        Broken{"other_scale", "--scale 1", "scale 0.5 in the checkpoint, 1 in this run",
               [](const fs::path &) {}},
        Broken{"other_grid", "--grid sorted", "grid table in the checkpoint, sorted",
               [](const fs::path &) {}},
        Broken{"other_code", "", "written by sph at commit 0000",
               [](const fs::path &ck) {
                   rewrite(sph::manifest_path(ck), [](std::string &s) {
                       const auto at = s.find("\"git_commit\": \"") + 15;
                       s.replace(at, s.find('"', at) - at, "0000");
                   });
               }},
        Broken{"no_manifest", "", "manifest.json does not exist",
               [](const fs::path &ck) { fs::remove(sph::manifest_path(ck)); }},
        Broken{"manifest_not_json", "", "not a checkpoint manifest",
               [](const fs::path &ck) {
                   rewrite(sph::manifest_path(ck), [](std::string &s) { s.resize(s.size() / 2); });
               }},
        Broken{"ends_before", "--steps 100", "this run ends at step 100", [](const fs::path &) {}}),
    [](const auto &info) { return info.param.name; });

// sph-scan-bench rebuilds every rank's slab window and grid from a checkpoint: the neighbours it
// finds are exactly those of an O(N^2) search over the rank's particles (owned and transient),
// in the order the run left them and in any other memory order.
struct ScanCase {
    std::string name, args;
    int ranks;
};
void PrintTo(const ScanCase &c, std::ostream *os) {
    *os << c.name;
}
class ScanBenchTest : public ::testing::TestWithParam<ScanCase> {};

TEST_P(ScanBenchTest, FindsTheBruteForceNeighboursOfEveryRank) {
    const ScanCase &c = GetParam();
    const auto dir = scratch("scan_bench_" + c.name);
    const auto ck = dir / "ck";
    const auto made = sph_run(c.ranks, c.args + " --steps 200 --checkpoint " + ck.string());
    ASSERT_EQ(made.code, 0) << made.err;
    const sph::Manifest m = sph::read_manifest(ck);
    sph::Physics phys;
    phys.delta = m.delta;
    phys.h = sph::Physics::h_factor * m.delta * std::sqrt(2.0);
    const double r2 = phys.cell_size() * phys.cell_size();
    std::vector<std::uint64_t> brute;
    for (int r = 0; r < c.ranks; ++r) {
        const auto path = ck / m.files[static_cast<std::size_t>(r)].name;
        const sph::RankState s = sph::deserialise_rank(sph::read_file(path), path.string());
        std::uint64_t n = 0;
        for (std::size_t i = 0; i < s.owned; ++i)
            for (std::size_t j = 0; j < s.x.size(); ++j) {
                const bool fluid = s.kind[i] == static_cast<std::uint8_t>(sph::Kind::fluid) ||
                                   s.kind[j] == static_cast<std::uint8_t>(sph::Kind::fluid);
                const double dx = s.x[i] - s.x[j], dy = s.y[i] - s.y[j];
                n += j != i && fluid && dx * dx + dy * dy < r2 ? 1 : 0;
            }
        brute.push_back(n);
    }
    EXPECT_GT(brute.front(), 0u);
    for (const char *arrangement : {"as-saved", "random-order", "cell-order"}) {
        const auto json = dir / (std::string(arrangement) + ".json");
        const auto r =
            run(bin("sph-scan-bench") + " --quiet --repeats 2 --checkpoint " + ck.string() +
                " --arrangement " + arrangement + " --json " + json.string());
        ASSERT_EQ(r.code, 0) << r.err;
        const auto report = nlohmann::json::parse(slurp(json));
        ASSERT_EQ(report["cases"].size(), static_cast<std::size_t>(c.ranks));
        for (int k = 0; k < c.ranks; ++k)
            EXPECT_EQ(report["cases"][k]["interactions"].get<std::uint64_t>(),
                      brute[static_cast<std::size_t>(k)])
                << arrangement << ", rank " << k;
    }
}

INSTANTIATE_TEST_SUITE_P(
    Sph, ScanBenchTest,
    ::testing::Values(ScanCase{"table_1", "--grid table", 1},
                      ScanCase{"table_2", "--grid table", 2},
                      ScanCase{"table_3", "--grid table", 3},
                      ScanCase{"table_balanced_2", "--grid table --decomposition balanced", 2},
                      ScanCase{"list_mirror_3", "--grid list --boundary mirror", 3}),
    [](const auto &info) { return info.param.name; });

TEST(ScanBench, RefusesACheckpointWithoutStoredListsInOneLine) {
    const auto dir = scratch("scan_bench_sorted");
    const auto ck = dir / "ck";
    const auto made = sph_run(1, "--grid sorted --steps 100 --checkpoint " + ck.string());
    ASSERT_EQ(made.code, 0) << made.err;
    const auto r = run(bin("sph-scan-bench") + " --quiet --checkpoint " + ck.string() + " --json " +
                       (dir / "s.json").string());
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(r.err_lines(), 1) << r.err;
    EXPECT_NE(r.err.find("ran --grid sorted: expected list or table"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir / "s.json"));
}
