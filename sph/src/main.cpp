// sph: the SPH proxy application (2D weakly compressible dam break), MPI slabs + OpenMP.
#include "sphperf/allocation.hpp"
#include "sphperf/cli.hpp"
#include "sphperf/model/comm_model.hpp"
#include "sphperf/model/memory.hpp"
#include "sphperf/model/placement.hpp"
#include "sphperf/model/profile.hpp"
#include "sphperf/model/runtime.hpp"
#include "sphperf/report.hpp"
#include "sphperf/sph/checkpoint.hpp"
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/simulation.hpp"
#include "sphperf/topology.hpp"

#include <mpi.h>
#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <unistd.h>

namespace {

using namespace sphperf;
using namespace sphperf::sph;

Config parse(int argc, char **argv) {
    Config cfg;
    std::string setup = "dambreak", grid = "table", boundary = "fixed", decomposition = "equal",
                halo_transport = "messages";
    std::int64_t steps = 0;
    double end_time = 0;
    cli::App app{"SPH proxy: 2D weakly compressible SPH (dam break, still tank, water column) "
                 "on MPI slabs with OpenMP threads, Cell+List, Cell+Table or Cell+Sorted grids, "
                 "instrumented for performance modelling. Launch with scripts/mpirun.sh -n RANKS."};
    app.add_option("--setup", setup, "dambreak, still or column");
    app.add_option("--grid", grid,
                   "Cell grid: list (Cell+List), table (Cell+Table) or sorted (particles in cell "
                   "order, no stored pairs)");
    app.add_option("--boundary", boundary, "Walls: mirror (Neumann) or fixed (Dirichlet)");
    app.add_option("--scale", cfg.scale, "Geometry scale factor (thesis Scale)")
        ->check(FinitePositive);
    app.add_option("--delta", cfg.physics.delta, "Particle spacing in metres")
        ->check(FinitePositive);
    app.add_option("--dt", cfg.dt, "Time step in seconds (checked against the CFL limit)")
        ->check(FinitePositive);
    auto *o_steps = app.add_option("--steps", steps, "Number of time steps")
                        ->check(cli::Range(std::int64_t{0}, std::int64_t{1} << 40));
    auto *o_end = app.add_option("--end-time", end_time, "Simulated time to reach, in seconds")
                      ->check(FiniteNonNegative);
    app.add_option(
           "--threads", cfg.threads,
           "OpenMP threads per rank (default OMP_NUM_THREADS, else SLURM_CPUS_PER_TASK, else the "
           "rank's bound cores shared by the node's ranks)")
        ->check(cli::Range(1, 1024));
    app.add_option("--interval", cfg.interval, "Steps per report interval")
        ->check(cli::Range(1, 1 << 30));
    app.add_option("--report", cfg.report, "Write the JSON report to this file");
    auto *o_machine =
        app.add_option("--machine", cfg.machine,
                       "machine.json: record per interval and rank the predicted time of the "
                       "messages actually sent (comm_predict_s; comm_hockney_s by ping-pong alone)")
            ->check(cli::ExistingFile);
    app.add_option("--exchange", cfg.exchange,
                   "An exchange benchmark report of this host at this run's rank count: cost the "
                   "shifts with it instead of the machine profile's (measure it right before the "
                   "run where exchange costs drift, see model/NOTES.md)")
        ->check(cli::ExistingFile)
        ->needs(o_machine);
    app.add_option("--replay-slice-ms", cfg.replay_slice_ms,
                   "With --machine above the cores (one-thread ranks on one node, blocking "
                   "exchanges): the scheduler slice, in ms, of the time-shared step's replay that "
                   "predicts comm_predict_s (1.5: the kernel's EEVDF base slice here; tuned, "
                   "model/NOTES.md)")
        ->check(FinitePositive)
        ->needs(o_machine);
    app.add_option("--vtk", cfg.vtk_dir, "Write ParaView snapshots (.vtu + sph.pvd) here");
    app.add_option("--vtk-every", cfg.vtk_every, "Steps between snapshots")
        ->check(cli::Range(1, 1 << 30));
    app.add_option("--column-width", cfg.column_width, "Width a of the column setup, metres")
        ->check(FinitePositive);
    app.add_option("--alpha", cfg.physics.alpha, "Artificial viscosity coefficient")
        ->check(FiniteNonNegative);
    app.add_option("--shepard-every", cfg.physics.shepard_every,
                   "Steps between Shepard density filters (0: never)")
        ->check(cli::Range(0, 1 << 30));
    app.add_option("--checkpoint", cfg.checkpoint_dir,
                   "Write checkpoints into this directory (one file per rank and a manifest; "
                   "the previous one stays valid until the new one is complete)");
    auto *o_ck_every =
        app.add_option("--checkpoint-every", cfg.checkpoint_every,
                       "Steps between checkpoints, a multiple of --interval (default: --interval)")
            ->check(cli::Range(1, 1 << 30));
    app.add_option("--restart", cfg.restart_dir,
                   "Continue from the latest checkpoint in this directory (same options; any "
                   "rank count)")
        ->check(cli::ExistingDirectory);
    app.add_option("--decomposition", decomposition,
                   "Slabs: equal (the thesis' equal widths) or balanced (cut points moved so "
                   "every rank's cost per step is as equal as whole columns allow)")
        ->capture_default_str()
        ->check(cli::IsMember({"equal", "balanced"}));
    auto *o_every = app.add_option("--rebalance-every", cfg.rebalance_every,
                                   "Balanced slabs: steps between re-cuts (default: --interval)")
                        ->check(cli::Range(1, 1 << 30));
    auto *o_model = app.add_option("--model", cfg.cost_model,
                                   "Balanced slabs: cut by the calibrated model's predicted "
                                   "seconds per column (model.json of sphmodel calibrate)")
                        ->check(cli::ExistingFile);
    app.add_option("--wall-weight", cfg.balance.walls,
                   "Balanced slabs: cost of a wall particle against a fluid particle's 1")
        ->capture_default_str()
        ->check(FiniteNonNegative)
        ->excludes(o_model);
    app.add_flag("--overlap", cfg.overlap,
                 "Cell+Sorted: exchange ghosts and their densities non-blocking, computing the "
                 "columns that need no ghost while they travel (hidden time: overlap_s, "
                 "comm_hidden_predict_s)");
    app.add_option("--halo-transport", halo_transport,
                   "How ghosts and their densities travel between ranks: messages (MPI "
                   "point-to-point, what sphperf's model costs) or window (an MPI-3 shared-memory "
                   "window, every rank on one node: packed into the sender's segment, landed from "
                   "it, no copy between; not with --machine)")
        ->capture_default_str()
        ->check(cli::IsMember({"messages", "window"}));
    app.add_option("--reorder-every", cfg.reorder_every,
                   "Cell+Sorted: steps between permuting the particles themselves into cell "
                   "order (0: never; the grid sorts a copy every step either way, and the "
                   "results are the same; measured slower on this problem, see sph/NOTES.md)")
        ->capture_default_str()
        ->check(cli::Range(0, 1 << 30));
    app.add_option("--speed-gauge-every", cfg.speed_gauge_every,
                   "Steps between samples of the speed gauge, a fixed piece of the density "
                   "pass's arithmetic on every thread that measures how fast the host runs "
                   "during the run (gauge_cpu_s per interval and rank; about 60 us a sample "
                   "here; 0: none), and with two or more threads the round trip of a cache "
                   "line between threads 0 and 1 (core_round_trip_s; 40 round trips)")
        ->capture_default_str()
        ->check(cli::Range(0, 1 << 30));
    app.add_flag("--quiet", cfg.quiet, "No progress line");
    parse_cli(app, argc, argv);

    cfg.setup = parse_setup(setup);
    cfg.grid = parse_grid(grid);
    cfg.boundary = parse_boundary(boundary);
    cfg.decomposition = parse_decomposition(decomposition);
    cfg.halo_transport = parse_halo_transport(halo_transport);
    if (cfg.halo_transport == HaloTransport::window && cfg.machine)
        throw UsageError("--halo-transport window with --machine: the inline prediction costs MPI "
                         "messages, and this transport sends none for ghosts and densities "
                         "(expected --halo-transport messages)");
    if (cfg.decomposition == Decomposition::balanced && !o_every->count())
        cfg.rebalance_every = cfg.interval;
    if (o_model->count() && cfg.decomposition == Decomposition::balanced) {
        const auto w = model::balance_weights(
            model::load_report(*cfg.cost_model, "sphmodel-calibration"), setup, grid,
            cfg.threads > 0 ? cfg.threads : omp_get_max_threads());
        cfg.balance = {w.fluid, w.walls, w.source};
    }
    if (o_steps->count())
        cfg.steps = steps;
    if (o_end->count())
        cfg.end_time = end_time;
    if (const char *fault = std::getenv("SPHPERF_INJECT_FAULT"))
        cfg.fault = parse_fault(fault);
    cfg.physics.h = Physics::h_factor * cfg.physics.delta * std::sqrt(2.0);
    if (cfg.vtk_dir && cfg.vtk_every == 0)
        cfg.vtk_every = cfg.interval;
    if (cfg.checkpoint_dir && !o_ck_every->count())
        cfg.checkpoint_every = cfg.interval;
    return cfg;
}

// Refuses, before anything is allocated, a run whose particles cannot fit in this node's
// available memory: at least the fluid particles of this node's ranks (an equal share of the
// job) times the memory model's bytes per particle and per interaction (45.6 neighbours per
// particle at this support, thesis and measured; the model is within 5-9 % of measured peak
// RSS, 172 B per particle measured against 181 counted for 7.2e7 particles on the sorted grid).
// Walls, ghosts and the fixed part come on top.
static_assert(sph::pair_records == (model::sorted_record_bytes > 0),
              "the memory model counts Cell+Sorted's pair records where sph builds them");
void check_memory(const Config &cfg, const Geometry &geo, int ranks_here, int ranks) {
    constexpr double neighbours = 45.6;
    const auto counts = model::memory_counts(to_string(cfg.grid));
    const double per_particle = counts.per_particle + neighbours * counts.per_interaction;
    const double particles = static_cast<double>(geo.fluid_particles()) * ranks_here / ranks;
    const double need = particles * per_particle;
    double available = 0;
    std::ifstream meminfo("/proc/meminfo");
    std::string key;
    double kib = 0;
    std::string unit;
    while (meminfo >> key >> kib >> unit)
        if (key == "MemAvailable:")
            available = kib * 1024;
    if (available <= 0)
        available = static_cast<double>(sysconf(_SC_AVPHYS_PAGES)) * sysconf(_SC_PAGESIZE);
    if (need > available) {
        char msg[320];
        std::snprintf(msg, sizeof msg,
                      "the run needs at least %.3g bytes (%.3g fluid particles on this node x "
                      "%.0f B each, grid %s), the node has %.3g bytes available: use a larger "
                      "--delta, a smaller --scale or more nodes",
                      need, particles, per_particle, std::string(to_string(cfg.grid)).c_str(),
                      available);
        throw UsageError(msg);
    }
}

// --exchange: the report, checked, as the profile's "exchange" section holding it alone. It
// must come from the profile's host and match this run's load (its rank count, one thread per
// rank as the benchmark runs): a set measured at another load would cost the shifts at the
// wrong level of time-sharing.
nlohmann::json exchange_override(const std::filesystem::path &path, const nlohmann::json &profile,
                                 int ranks, int threads) {
    const std::string where = path.string();
    if (ranks < 2)
        throw UsageError("--exchange '" + where +
                         "' given to a 1-rank run, which sends no message");
    if (threads != 1)
        throw UsageError("--exchange '" + where +
                         "' costs one-thread ranks as the benchmark ran, "
                         "this run has " +
                         std::to_string(threads) + " threads per rank");
    const auto report = model::load_report(path, "exchange");
    model::check_report(report, "exchange", where);
    const auto host = report.value("host", std::string());
    if (host != profile.value("host", std::string()))
        throw UsageError("--exchange '" + where + "' was measured on host '" + host +
                         "', the machine profile on '" + profile.value("host", std::string()) +
                         "' (expected the same host)");
    const int measured = report.at("ranks").get<int>();
    if (measured != ranks)
        throw UsageError("--exchange '" + where + "' ran on " + std::to_string(measured) +
                         " ranks, this run has " + std::to_string(ranks) +
                         " (run the exchange benchmark on " + std::to_string(ranks) + ")");
    nlohmann::json section = nlohmann::json::object();
    section["exchange"] = nlohmann::json::array({report});
    (void)model::ExchangeModel::from_profile(section); // refuses malformed points here
    return section;
}

// A restart's checkpoint and the output paths are checked by rank 0 before any work; the
// verdict is shared.
void check_outputs(const Config &cfg, const Geometry &geo, int rank, int ranks) {
    // Ranks sharing this node's memory.
    MPI_Comm node;
    MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, rank, MPI_INFO_NULL, &node);
    int ranks_here = 1;
    MPI_Comm_size(node, &ranks_here);
    MPI_Comm_free(&node);
    std::string error;
    if (rank == 0) {
        try {
            check_memory(cfg, geo, ranks_here, ranks);
            if (cfg.halo_transport == HaloTransport::window && ranks_here != ranks)
                throw UsageError("--halo-transport window: " + std::to_string(ranks_here) +
                                 " of the job's " + std::to_string(ranks) +
                                 " ranks share this node; expected all of them on one node "
                                 "(or --halo-transport messages)");
            if (cfg.exchange)
                (void)exchange_override(*cfg.exchange, model::load_report(*cfg.machine, "machine"),
                                        ranks, omp_get_max_threads());
            // A restart is checked whole first, so a bad checkpoint overwrites nothing.
            if (cfg.restart_dir)
                (void)verify_checkpoint(*cfg.restart_dir, cfg);
            if (cfg.checkpoint_dir) {
                std::error_code ec;
                std::filesystem::create_directories(*cfg.checkpoint_dir, ec);
                if (!std::filesystem::is_directory(*cfg.checkpoint_dir))
                    throw UsageError("cannot create checkpoint directory '" +
                                     cfg.checkpoint_dir->string() + "'");
            }
            if (cfg.report)
                JsonSink::check_writable(*cfg.report);
            if (cfg.vtk_dir) {
                std::error_code ec;
                std::filesystem::create_directories(*cfg.vtk_dir, ec);
                if (!std::filesystem::is_directory(*cfg.vtk_dir))
                    throw UsageError("cannot create snapshot directory '" + cfg.vtk_dir->string() +
                                     "'");
            }
        } catch (const UsageError &e) {
            error = e.what();
        }
    }
    int ok = error.empty();
    MPI_Bcast(&ok, 1, MPI_INT, 0, MPI_COMM_WORLD);
    if (!ok) {
        if (rank == 0)
            throw UsageError(error);
        throw ExitRequest{exit_usage};
    }
}

// The first processing unit this rank is bound to, or -1 when it may run anywhere.
int bound_pu() {
    const Topology topo;
    const CpuSet set = topo.this_process_binding();
    return set.weight() > 0 && set.weight() < topo.pus() ? set.first() : -1;
}

// Each message to a neighbour is costed with the link between the two ranks' units (Hockney);
// each shift, when the profile has exchange measurements, as the exchange benchmark saw it at
// this rank count and after the compute that preceded it. Within the cores the run also probes
// the latency mode every interval; returns the profile's figure for that probe (0: no probe).
double attach_message_costs(Domain &domain, const Config &cfg, const std::vector<int> &pus,
                            int threads) {
    const auto profile = model::load_report(*cfg.machine, "machine");
    auto comm = std::make_shared<model::CommModel>(model::CommModel::from_profile(profile));
    domain.enable_cpu_segments(); // the time-shared replay's input (replay_time_shared_comm)
    const auto exchange = model::ExchangeModel::from_profile(
        cfg.exchange ? exchange_override(*cfg.exchange, profile, domain.ranks(), threads)
                     : profile);
    double probe_s = 0;
    bool overlap_measured = false;
    constexpr double probe_bytes = 64; // Domain::probe_latency's payload
    if (!exchange.empty()) {
        const auto set = std::make_shared<model::ExchangeSet>(
            exchange.set_for(domain.ranks(), threads, Topology().cores()));
        domain.attach_shift_cost([set](double since_any_s, double since_kind_s, double bytes) {
            using model::ExchangeModel, model::GapRule;
            return ShiftPrediction{
                ExchangeModel::app_shift_seconds(*set, since_any_s, since_kind_s, bytes),
                ExchangeModel::app_shift_seconds(*set, since_any_s, since_kind_s, bytes,
                                                 GapRule::own_kind_gap)};
        });
        if (set->has(model::ShiftMode::overlapped)) {
            overlap_measured = true;
            domain.attach_exposed_cost([set](double behind_s, double bytes) {
                return model::ExchangeModel::shift_seconds(*set, behind_s, bytes,
                                                           model::ShiftMode::overlapped);
            });
        }
        // Above the cores a back-to-back shift waits for descheduled neighbours: no mode shows.
        // The probe is collective: every rank must agree (nodes may differ in cores).
        const bool within = set->load() <= 1 && domain.ranks() > 1;
        if (domain.max(within ? 0.0 : 1.0) == 0.0) {
            domain.enable_latency_probe();
            probe_s = model::ExchangeModel::shift_seconds(*set, 0.0, probe_bytes);
        }
    }
    const int me = pus[static_cast<std::size_t>(domain.rank())];
    // A message to (outgoing) or from a neighbour, costed on the link between the two units.
    auto link = [&](int neighbour, bool outgoing) -> MessageCost {
        if (neighbour == MPI_PROC_NULL)
            return {};
        const int other = pus[static_cast<std::size_t>(neighbour)];
        const int a = outgoing ? me : other, b = outgoing ? other : me;
        return [comm, a, b](double bytes) { return comm->seconds(a, b, bytes); };
    };
    domain.attach_cost(link(domain.west(), true), link(domain.east(), true));
    // --overlap without an overlapped exchange measurement: a received payload costs at least
    // its one-way Hockney time, exposed whatever the compute behind it (sph/README.md).
    if (!overlap_measured)
        domain.attach_overlap_cost(link(domain.west(), false), link(domain.east(), false));
    return probe_s;
}

void print_summary(const nlohmann::json &r) {
    const auto &c = r["config"];
    std::printf("sph: %s, grid %s, boundary %s, scale %g, %lld fluid particles, %lld steps, "
                "%d rank(s) x %d thread(s)\n",
                c["setup"].get<std::string>().c_str(), c["grid"].get<std::string>().c_str(),
                c["boundary"].get<std::string>().c_str(), c["scale"].get<double>(),
                r["particles"]["field"].get<long long>(), c["steps"].get<long long>(),
                c["ranks"].get<int>(), c["threads"].get<int>());
    std::printf("  wall %.3f s, %.1f steps/s, %.3g particle-steps/s, %.3g interactions/s\n",
                r["wall_s"].get<double>(), r["steps_per_s"].get<double>(),
                r["particle_steps_per_s"].get<double>(),
                r["neighbour_interactions_per_s"].get<double>());
    std::printf("  phase times (max over ranks):");
    for (const auto &[k, v] : r["totals"]["timers"].items())
        std::printf(" %s %.3f", k.c_str(), v["max"].get<double>());
    const auto &ph = r["physics"];
    std::printf("\n  front_x %.4f m at t=%.4f s\n", ph["front_x"].back().get<double>(),
                ph["time_s"].back().get<double>());
}

// Above the cores the exchange benchmark (every rank the same work) cannot say which rank the
// scheduler parks: each interval's inline prediction is then the step replayed from every
// rank's measured CPU time before each shift (model::replay_time_shared), each rank on the core
// its unit belongs to. One-thread ranks on one node with blocking exchanges only; otherwise the
// exchange benchmark's stands. Run on rank 0 after the run, so it perturbs no step.
void replay_time_shared_comm(RunRecord &rec, const Config &cfg, int threads) {
    rec.comm_predict_source = "exchange benchmark";
    const auto &pus = rec.placement_pus;
    const auto &nodes = rec.placement_nodes;
    if (threads != 1 || cfg.overlap || pus.size() < 2 ||
        std::any_of(pus.begin(), pus.end(), [](int p) { return p < 0; }) ||
        std::any_of(nodes.begin(), nodes.end(), [&](const auto &n) { return n != nodes[0]; }))
        return;
    const Topology topo;
    std::vector<int> core_of(pus.size());
    int cores = 0;
    bool shared = false;
    for (std::size_t r = 0; r < pus.size(); ++r) {
        core_of[r] = -1;
        for (std::size_t q = 0; q < r && core_of[r] < 0; ++q)
            if (topo.classify(pus[q], pus[r]) == Locality::same_core)
                core_of[r] = core_of[q];
        shared = shared || core_of[r] >= 0;
        if (core_of[r] < 0)
            core_of[r] = cores++;
    }
    if (!shared)
        return;
    rec.comm_predict_source = "time-shared step replayed";
    for (auto &iv : rec.intervals) {
        std::vector<std::array<double, 3>> cpu;
        for (const auto &r : iv.ranks) {
            const double n = std::max(r.steps, 1.0);
            cpu.push_back({r.segment_cpu_s[0] / n, r.segment_cpu_s[1] / n, r.segment_cpu_s[2] / n});
        }
        const auto rep = model::replay_time_shared(cpu, core_of, 1e-3 * cfg.replay_slice_ms);
        for (std::size_t r = 0; r < iv.ranks.size(); ++r) {
            auto &ri = iv.ranks[r];
            ri.comm_predict_s = 0;
            // The gap rules apply within the cores only: both forms are the replay's here.
            for (std::size_t k = 0; k < ri.shift_predict_s.size(); ++k) {
                ri.shift_predict_s[k] = ri.shift_predict_own_kind_s[k] =
                    rep.shift_comm_s[r][k] * ri.steps;
                ri.comm_predict_s += ri.shift_predict_s[k];
            }
        }
    }
}

void simulate(const Config &cfg, const Geometry &geo, int rank) {
    Domain domain(MPI_COMM_WORLD, geo.cell_columns, geo.cell_size);
    if (cfg.halo_transport == HaloTransport::window)
        domain.use_window_halo();
    const std::vector<int> pus = domain.gather_int(bound_pu());
    const double profile_probe_s =
        cfg.machine ? attach_message_costs(domain, cfg, pus, omp_get_max_threads()) : 0.0;
    RunRecord rec = cfg.grid == GridKind::list    ? Simulation<CellList>(cfg, geo, domain).run()
                    : cfg.grid == GridKind::table ? Simulation<CellTable>(cfg, geo, domain).run()
                                                  : Simulation<CellSorted>(cfg, geo, domain).run();
    rec.placement_pus = pus;
    rec.profile_probe_shift_s = profile_probe_s;
    rec.placement_nodes = domain.gather_string(node_name());
    if (rank == 0 && cfg.machine)
        replay_time_shared_comm(rec, cfg, omp_get_max_threads());
    if (rank == 0) {
        const Topology topo;
        const nlohmann::json report = build_report(rec, topo);
        print_summary(report);
        JsonSink(cfg.report).write(report);
    }
}

int run(int argc, char **argv, int rank, int ranks) {
    Config cfg = parse(argc, argv);
    const Geometry geo = make_geometry(cfg);
    validate(cfg, geo, ranks);
    const Topology topo;
    if (cfg.threads > 0)
        omp_set_num_threads(cfg.threads);
    else if (!std::getenv("OMP_NUM_THREADS"))
        omp_set_num_threads(default_threads(topo));
    check_outputs(cfg, geo, rank, ranks); // after the thread count: --exchange checks it

    {
        // Threads beyond the cores this rank may run on only take turns: say so (rank 0).
        // With OMP_PROC_BIND the runtime has already bound this thread to one place, before the
        // team exists: the team's cores are then the places.
        const int places = omp_get_proc_bind() != omp_proc_bind_false ? omp_get_num_places() : 0;
        const int bound = places > 0 ? places : topo.this_process_binding().weight();
        const int threads = omp_get_max_threads();
        const bool shared_binding = bound > 0 && threads > bound;
        if (rank == 0 && shared_binding)
            std::fprintf(stderr,
                         "sph: warning: %d threads share the %d core(s) this rank is bound to; "
                         "launch with scripts/mpirun.sh -n RANKS -t THREADS\n",
                         threads, bound);
        // And ranks x threads beyond the node's (or the Slurm allocation's) cores.
        const int local = ranks_on_node();
        const int allocated = env_count("SLURM_CPUS_ON_NODE");
        const int cores = allocated > 0 ? allocated : topo.pus();
        if (rank == 0 && local * threads > cores)
            std::fprintf(stderr,
                         "sph: warning: %d ranks x %d threads on this node exceed its %d "
                         "core(s)%s; they take turns\n",
                         local, threads, cores, allocated > 0 ? " in the Slurm allocation" : "");
        // Threads taking turns would pass the gauge's line a time slice at a time.
        cfg.core_latency_gauge = !shared_binding && local * threads <= cores;
    }
    // From here on an error may strike one rank only, while the others wait in an exchange:
    // it ends the whole job (MPI_Abort), naming the rank, instead of leaving them waiting.
    try {
        simulate(cfg, geo, rank);
    } catch (const ExitRequest &) {
        throw;
    } catch (const std::exception &e) {
        const int code = dynamic_cast<const UsageError *>(&e) ? exit_usage : exit_failure;
        if (ranks == 1)
            throw;
        std::fprintf(stderr, "sph: %s: rank %d of %d: %s\n", code == exit_usage ? "error" : "fatal",
                     rank, ranks, e.what());
        std::fflush(stderr);
        MPI_Abort(MPI_COMM_WORLD, code);
    }
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    int provided = 0;
    MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
    int rank = 0, ranks = 1;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &ranks);
    if (rank != 0) { // rank 0 speaks for all; the others return the same code silently
        std::cout.setstate(std::ios::failbit);
        std::cerr.setstate(std::ios::failbit);
    }
    const int code = sphperf::guarded_main("sph", [&] { return run(argc, argv, rank, ranks); });
    MPI_Finalize();
    return code;
}
