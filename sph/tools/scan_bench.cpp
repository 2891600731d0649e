// sph-scan-bench: the stored-list neighbour search (pass 1, what sph books as pairs_s) timed
// alone on the particles of checkpointed ranks, all of them in one process and alternated, so
// that slabs are compared at one host speed. The arrangement of the particles can be perturbed
// (lattice jitter or shift, memory order) and the caches flushed between searches: this is how
// sph/NOTES.md (session 83) told what the search's cost per interaction depends on.
#include "sphperf/cli.hpp"
#include "sphperf/report.hpp"
#include "sphperf/sph/balance.hpp"
#include "sphperf/sph/checkpoint.hpp"
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/grid.hpp"
#include "sphperf/timer.hpp"
#include "sphperf/topology.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <optional>
#include <random>
#include <string>
#include <variant>
#include <vector>

namespace {

using namespace sphperf;
using namespace sphperf::sph;

struct BenchConfig {
    std::vector<std::string> checkpoints;
    int repeats = 40;
    std::string arrangement = "as-saved";
    double amount = 0.2; // of the particle spacing (jitter, shift)
    double flush_mb = 0; // written between searches: 0 for none
    std::uint64_t seed = 1;
    std::optional<std::filesystem::path> json;
    bool quiet = false;
};

BenchConfig parse(int argc, char **argv) {
    BenchConfig c;
    cli::App app{"Times the stored-list neighbour search (Cell+List, Cell+Table: the pass sph "
                 "books as pairs_s) alone on every rank of sph checkpoints, one process, the "
                 "ranks alternated, optionally with the particles' arrangement perturbed."};
    app.always_capture_default();
    app.add_option("--checkpoint", c.checkpoints,
                   "Checkpoint directories (sph --checkpoint) whose latest step is timed, every "
                   "rank")
        ->required()
        ->check(cli::ExistingDirectory);
    app.add_option("--repeats", c.repeats, "Searches timed per rank")->check(cli::Range(1, 100000));
    app.add_option("--arrangement", c.arrangement,
                   "as-saved (the grid's state as checkpointed), jitter (every fluid particle "
                   "moved by up to --amount spacings in x and y), shift (every particle moved by "
                   "--amount spacings in x and y), random-order (the owned particles' memory "
                   "order shuffled), cell-order (sorted by cell)")
        ->check(cli::IsMember({"as-saved", "jitter", "shift", "random-order", "cell-order"}));
    app.add_option("--amount", c.amount, "Jitter or shift, in particle spacings")
        ->check(FiniteNonNegative);
    app.add_option("--flush-mb", c.flush_mb,
                   "Megabytes written between two searches to evict the caches (0: none)")
        ->check(cli::Range(0.0, 65536.0));
    app.add_option("--seed", c.seed, "Random seed of jitter and random-order");
    app.add_option("--json", c.json, "Write the JSON report to this file");
    app.add_flag("--quiet", c.quiet, "No progress line");
    parse_cli(app, argc, argv);
    return c;
}

// One rank's state, its grid filed as the run left it.
template <class Grid> struct Case {
    std::string checkpoint;
    int rank = 0;
    Particles p;
    Grid grid;
    CellWindow window;
    NeighbourList nl;
    std::uint64_t candidates = 0;
    std::vector<double> scan_s;
};

Config config_of(const Manifest &m) {
    Config cfg;
    cfg.setup = parse_setup(m.setup);
    cfg.grid = parse_grid(m.grid);
    cfg.scale = m.scale;
    cfg.physics.delta = m.delta;
    cfg.column_width = m.column_width;
    cfg.physics.h = Physics::h_factor * cfg.physics.delta * std::sqrt(2.0);
    return cfg;
}

void rearrange(Particles &p, const CellWindow &w, const BenchConfig &c, double delta,
               std::mt19937_64 &rng) {
    if (c.arrangement == "jitter" || c.arrangement == "shift") {
        std::uniform_real_distribution<double> u(-c.amount * delta, c.amount * delta);
        const bool jitter = c.arrangement == "jitter";
        const std::size_t n = jitter ? p.fluid() : p.size();
        for (std::size_t i = 0; i < n; ++i) {
            p.x[i] += jitter ? u(rng) : c.amount * delta;
            p.y[i] += jitter ? u(rng) : c.amount * delta;
        }
        return;
    }
    if (c.arrangement != "random-order" && c.arrangement != "cell-order")
        return;
    // Particles::permute takes owned particles only: the transient ones step aside meanwhile.
    std::vector<ParticleRecord> transient;
    for (std::size_t i = p.owned(); i < p.size(); ++i)
        transient.push_back(p.record(i));
    p.drop_transient();
    std::vector<std::uint32_t> order(p.owned());
    std::iota(order.begin(), order.end(), 0u);
    const auto fluid_end = order.begin() + static_cast<std::ptrdiff_t>(p.fluid());
    if (c.arrangement == "random-order") {
        std::shuffle(order.begin(), fluid_end, rng);
        std::shuffle(fluid_end, order.end(), rng);
    } else {
        const auto by_cell = [&](std::uint32_t a, std::uint32_t b) {
            return w.cell_of(p.x[a], p.y[a]) < w.cell_of(p.x[b], p.y[b]);
        };
        std::stable_sort(order.begin(), fluid_end, by_cell);
        std::stable_sort(fluid_end, order.end(), by_cell);
    }
    p.permute(order);
    for (const auto &r : transient)
        p.add_transient(r);
}

// Everything the search examines: the particles of the 3 x 3 cells of every owned particle.
template <class Grid> std::uint64_t count_candidates(const Case<Grid> &k) {
    std::uint64_t n = 0;
    const auto &w = k.window;
    for (std::size_t i = 0; i < k.p.owned(); ++i) {
        const int ci = w.column_of(k.p.x[i]), ri = w.row_of(k.p.y[i]);
        for (int c = std::max(ci - 1, w.col_begin); c <= std::min(ci + 1, w.col_end - 1); ++c)
            for (int r = std::max(ri - 1, w.row_begin); r <= std::min(ri + 1, w.row_end - 1); ++r)
                k.grid.for_each_in_cell(w.cell(c, r), k.p, [&](std::uint32_t) { ++n; });
    }
    return n;
}

template <class Grid>
void load(std::vector<Case<Grid>> &cases, const std::filesystem::path &dir, const Manifest &m,
          const BenchConfig &c, std::mt19937_64 &rng) {
    const Config cfg = config_of(m);
    const Geometry geo = make_geometry(cfg);
    const std::vector<int> cuts = m.cuts.empty() ? equal_cuts(m.ranks, geo.cell_columns) : m.cuts;
    for (int r = 0; r < m.ranks; ++r) {
        // The manifest names the rank files first, in rank order, then the record.
        const auto path = dir / m.files.at(static_cast<std::size_t>(r)).name;
        const RankState s = deserialise_rank(read_file(path), path.string());
        Case<Grid> &k = cases.emplace_back();
        k.checkpoint = dir.string();
        k.rank = r;
        s.restore(k.p);
        k.window = slab_window(cfg.physics.cell_size(), cuts[static_cast<std::size_t>(r)],
                               cuts[static_cast<std::size_t>(r) + 1], geo.cell_rows);
        rearrange(k.p, k.window, c, cfg.physics.delta, rng);
        if (c.arrangement == "as-saved")
            k.grid.restore_state(s.grid_state);
        k.grid.update(k.p, k.window);
        k.candidates = count_candidates(k);
    }
}

nlohmann::json summary_of(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return {{"median_s", v[v.size() / 2]}, {"min_s", v.front()}, {"max_s", v.back()}};
}

template <class Grid> nlohmann::json bench(const std::vector<Manifest> &ms, const BenchConfig &c) {
    std::mt19937_64 rng(c.seed);
    std::vector<Case<Grid>> cases;
    for (std::size_t i = 0; i < ms.size(); ++i)
        load(cases, c.checkpoints[i], ms[i], c, rng);
    std::vector<double> junk(static_cast<std::size_t>(c.flush_mb * (1 << 20) / sizeof(double)));
    double sink = 0;
    const double start = wall_seconds();
    for (int rep = 0; rep < c.repeats; ++rep) {
        for (auto &k : cases) {
            if (k.p.owned() == 0)
                continue;
            if (!junk.empty()) {
                for (double &v : junk)
                    v += 1.0;
                sink += junk[static_cast<std::size_t>(rep) % junk.size()];
            }
            const double t0 = wall_seconds();
            const PairCounts counts =
                find_neighbours(k.grid, k.p, k.window, k.window.cell_size, k.nl);
            k.scan_s.push_back(wall_seconds() - t0 - counts.sort_s);
        }
        if (!c.quiet && (rep + 1) % 10 == 0)
            std::fprintf(stderr, "sph-scan-bench: %d/%d rounds (%.0f s)\n", rep + 1, c.repeats,
                         wall_seconds() - start);
    }
    nlohmann::json out = nlohmann::json::array();
    std::printf("%-40s %4s %8s %8s %11s %10s %12s %10s\n", "checkpoint", "rank", "owned", "fluid",
                "interact.", "cand/int.", "ns/int. med", "min");
    for (const auto &k : cases) {
        const double interactions = static_cast<double>(k.nl.index.size());
        nlohmann::json j{{"checkpoint", k.checkpoint},
                         {"rank", k.rank},
                         {"owned", k.p.owned()},
                         {"fluid", k.p.fluid()},
                         {"interactions", k.nl.index.size()},
                         {"candidates", k.candidates}};
        if (!k.scan_s.empty() && interactions > 0) {
            j["scan"] = summary_of(k.scan_s);
            const double med = j["scan"]["median_s"], lo = j["scan"]["min_s"];
            j["scan_per_interaction_median_s"] = med / interactions;
            std::printf("%-40s %4d %8zu %8zu %11.0f %10.3f %12.3f %10.3f\n", k.checkpoint.c_str(),
                        k.rank, k.p.owned(), k.p.fluid(), interactions,
                        static_cast<double>(k.candidates) / interactions, med / interactions * 1e9,
                        lo / interactions * 1e9);
        }
        out.push_back(std::move(j));
    }
    if (sink == -1.0) // keeps the flush from being optimised away
        std::puts("");
    return out;
}

int run(int argc, char **argv) {
    const BenchConfig c = parse(argc, argv);
    const JsonSink sink(c.json);
    std::vector<Manifest> ms;
    for (const auto &dir : c.checkpoints) {
        ms.push_back(read_manifest(dir));
        if (ms.back().grid != "table" && ms.back().grid != "list")
            throw UsageError("checkpoint '" + dir + "' ran --grid " + ms.back().grid +
                             ": expected list or table (the stored-list search)");
        if (ms.back().grid != ms.front().grid)
            throw UsageError("checkpoint '" + dir + "' ran --grid " + ms.back().grid + ", '" +
                             c.checkpoints.front() + "' --grid " + ms.front().grid +
                             ": expected one grid per bench");
    }
    omp_set_num_threads(1); // one thread: the search's own cost, not the threads' balance
    const nlohmann::json cases =
        ms.front().grid == "table" ? bench<CellTable>(ms, c) : bench<CellList>(ms, c);
    if (sink.enabled()) {
        const Topology topo(TopologyScope::binding);
        nlohmann::json report = report_header("sph-scan-bench", topo);
        report["grid"] = ms.front().grid;
        report["threads"] = 1;
        report["repeats"] = c.repeats;
        report["arrangement"] = c.arrangement;
        report["amount_spacings"] = c.amount;
        report["flush_bytes"] = static_cast<std::uint64_t>(c.flush_mb * (1 << 20));
        report["timed"] = "find_neighbours minus its id sort (sph's pairs_s)";
        report["cases"] = cases;
        sink.write(report);
    }
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    return sphperf::guarded_main("sph-scan-bench", [&] { return run(argc, argv); });
}
