// sphmodel predict: workload per rank from the re-cut trace, work from the regressions, cost
// from the fitted compute model and the Hockney links, then the blocking exchange's wait, the
// idle ranks, and time-sharing when ranks x threads exceed the cores.
#include "sphperf/errors.hpp"
#include "sphperf/model/interpolate.hpp"
#include "sphperf/model/jitter.hpp"
#include "sphperf/model/placement.hpp"
#include "sphperf/model/runtime.hpp"

#include "sphperf/sph/balance.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <optional>

namespace sphperf::model {

namespace {
using nlohmann::json;

constexpr int samples_per_interval = 4; // workload sampled at interval quarter-midpoints
constexpr double count_bytes = sizeof(int);
constexpr double density_bytes = sizeof(double);
constexpr double shifts_per_step = 3; // migration, ghosts, density refresh
// Of which the ghosts come right after the migration: within the cores the other two split the
// step between them.
constexpr double blocking_shifts_per_step = 2;

struct Costs {
    LinearFit pairs, exports, interactions, compute, cell_moves;
    // The core round trip the compute term core_round_trips costs (the calibration's mean;
    // model.json compute[i].core_round_trip_s), and that object whole for the report.
    double core_round_trip_s = 0;
    json core_round_trip;
    std::optional<Disorder> disorder; // list and table: memory order against simulated time
    // List and table: the memory order per column, so each rank's compute per interaction
    // follows its own columns' (predict --rank-disorder columns).
    std::optional<ColumnDisorder> column_disorder;
    // Cell+Table with the Froude-time profile: the whole water's memory order over simulated
    // time, to which each equal slab's is carried (predict --memory-order-time simulated).
    std::optional<Disorder> order_level;
    double delta = 0.01; // target spacing (acoustic time of the disorder record)
    // Measured / fitted compute of this setup by Froude time (calibrate --time-profile froude);
    // empty: none. The target's scale turns its time into Froude time.
    std::vector<std::pair<double, double>> profile;
    double profile_end = 0; // Froude time the profile's runs reach
    double scale = 1;
    // Every compute time's factor from the model's reference speed to the one predicted at
    // (predict --host-speed: 1 at the median run's, speed_gauge.mean_factor at the mean).
    double host_speed = 1;
    CommModel comm;
    ExchangeModel exchange; // empty: the shifts are costed message by message with Hockney
    double record_bytes = 72;
    int cores = 1;
    bool overlap = false; // sph --overlap: ghosts and densities behind the interior columns
    // Time-sharing overhead measured on the app's own calibration runs, by load (ranks x
    // threads / cores); a load it did not run falls back to the exchange benchmark's.
    // Per load: the median seconds per step added on a shared core, and the ratio (session 33's
    // model); with runs of several step lengths whose slope is significant, also the line
    // a + b x the shared core's compute per step (session 36; used with
    // --time-sharing-overhead line only since session 37: in use in two blind main jobs it put
    // the balanced 4-rank dam break +8.0 and +26.5 %, the median -4.2 and within 8.6 %).
    struct Sharing {
        double seconds_per_step = 0, ratio = 1, line_intercept = 0, per_compute = 0;
        bool line = false; // a significant line was fitted
    };
    std::map<double, Sharing> sharing;
    bool sharing_ratio = false; // predict --time-sharing-overhead ratio
    bool sharing_line = false;  // predict --time-sharing-overhead line
    // predict --time-sharing-overhead replay: a shared node's step replayed
    // (replay_time_shared) with this slice and the calibration's segment shares of compute
    bool sharing_replay = false;
    // The replay's pipeline bubble where every core time-shares two busy ranks (calibrate's
    // time_sharing_bubble; 0: none or --time-sharing-bubble off): a replayed step x (1 + k phi).
    double bubble_per_phi = 0;
    double replay_slice_s = default_replay_slice_s;
    std::optional<std::array<double, 3>> segment_shares;
    // Step-to-step jitter of a rank's compute (k 0: none measured); within the cores a step
    // lasts the expected maximum over the ranks.
    Jitter jitter;
    // Peak RSS per rank (model/NOTES.md "Memory"); absent in a model without calibration RSS.
    double bytes_per_particle = 0, bytes_per_interaction = 0, fixed_bytes = 0;
};

// Thesis Eqs. 4.4 and 4.5: particles 2 n m, pairs n m k / 2 with k = 32 x 9 candidate
// neighbours; its pessimistic upper bound, with m our bytes per stored particle.
constexpr double thesis_k = 32 * 9;

Costs costs_of(const json &model, const std::string &setup, const std::string &grid, int threads) {
    Costs c;
    try {
        if (!model.at("regressions").contains(setup))
            throw UsageError("the model has no pair regressions of setup '" + setup +
                             "': calibrate with a " + setup + " run");
        const auto &reg = model.at("regressions").at(setup);
        c.pairs = LinearFit::from_json(reg.at("pairs"), "model regressions");
        c.exports = LinearFit::from_json(reg.at("exports"), "model regressions");
        c.interactions = LinearFit::from_json(reg.at("interactions"), "model regressions");
        bool found = false;
        std::string have;
        for (const auto &m : model.at("compute")) {
            have += (have.empty() ? "" : ", ") + m.at("grid").get<std::string>() + "/" +
                    std::to_string(m.at("threads").get<int>());
            if (m.at("grid") == grid && m.at("threads") == threads) {
                c.compute = compute_cost_of(m, setup);
                found = true;
                if (std::find(c.compute.terms.begin(), c.compute.terms.end(), "core_round_trips") !=
                    c.compute.terms.end()) {
                    if (!m.contains("core_round_trip_s") ||
                        !m.at("core_round_trip_s").contains("mean"))
                        throw UsageError("model compute " + grid + "/" + std::to_string(threads) +
                                         " costs core round trips but has no "
                                         "core_round_trip_s/mean to cost them at");
                    c.core_round_trip = m.at("core_round_trip_s");
                    c.core_round_trip_s = c.core_round_trip.at("mean").get<double>();
                    if (!std::isfinite(c.core_round_trip_s) || c.core_round_trip_s <= 0)
                        throw UsageError("model compute " + grid + "/" + std::to_string(threads) +
                                         " core_round_trip_s/mean is not a positive time");
                }
                if (m.contains("segment_shares") && !m.at("segment_shares").is_null()) {
                    const auto &g = m.at("segment_shares");
                    c.segment_shares = std::array<double, 3>{
                        g.at("before_migration").get<double>(), g.at("before_ghosts").get<double>(),
                        g.at("before_densities").get<double>()};
                }
                if (m.contains("time_profile") && m.at("time_profile").contains(setup)) {
                    const auto &p = m.at("time_profile").at(setup);
                    const auto t = p.at("froude_time_s").get<std::vector<double>>();
                    const auto f = p.at("factor").get<std::vector<double>>();
                    if (t.size() != f.size() || t.empty())
                        throw UsageError("model compute " + grid + " time_profile/" + setup +
                                         " has " + std::to_string(t.size()) + " times and " +
                                         std::to_string(f.size()) + " factors");
                    for (std::size_t k = 0; k < t.size(); ++k) {
                        if (!std::isfinite(f[k]) || f[k] <= 0 || (k > 0 && t[k] < t[k - 1]))
                            throw UsageError("model compute " + grid + " time_profile/" + setup +
                                             " is not a positive factor over sorted times");
                        c.profile.emplace_back(t[k], f[k]);
                    }
                    c.profile_end = p.at("end_froude_time_s").get<double>();
                }
            }
        }
        if (!found)
            throw UsageError("the model has no compute cost for grid " + grid + " at " +
                             std::to_string(threads) + " thread(s) (it has " + have +
                             "): calibrate with such a run");
        if (!model.at("cell_moves").contains(grid))
            throw UsageError("the model has no cell-move fit for grid " + grid);
        c.cell_moves = LinearFit::from_json(model.at("cell_moves").at(grid), "model cell_moves");
        const bool needs_disorder = std::find(c.compute.terms.begin(), c.compute.terms.end(),
                                              "descents") != c.compute.terms.end();
        if (needs_disorder) {
            if (!model.contains("disorder") || !model.at("disorder").contains(setup) ||
                !model.at("disorder").at(setup).contains(grid))
                throw UsageError("the compute cost of grid " + grid + " has a memory-order " +
                                 "term but the model has no memory-order record of setup '" +
                                 setup + "' on that grid: calibrate with a " + grid + " run of it");
            c.disorder = Disorder::from_json(model.at("disorder").at(setup).at(grid),
                                             "model disorder " + setup + "/" + grid);
        }
        if (model.contains("disorder") && model.at("disorder").contains(setup) &&
            model.at("disorder").at(setup).contains(grid) &&
            model.at("disorder").at(setup).at(grid).contains("by_column")) {
            c.column_disorder =
                ColumnDisorder::from_json(model.at("disorder").at(setup).at(grid).at("by_column"),
                                          "model disorder " + setup + "/" + grid + "/by_column");
            if (const std::string why = c.column_disorder->unusable(); !why.empty())
                throw UsageError("model disorder " + setup + "/" + grid + "/by_column: " + why +
                                 " (calibrate keeps such a line under by_column_unused)");
            // Cell+Table's own descents count its id sort's work, and they follow simulated
            // time; Cell+List's line reads Cell+Table's descents, but its lists come out
            // reversed whatever the order (0.86 descents per interaction), and its cost
            // follows the flow (Froude time): scale-1 runs over the half-scale record at equal
            // Froude time, median over 19 stored jobs, id sort 0.91 -> 1.08 for Cell+Table,
            // 0.87-0.95 for Cell+List (model/NOTES.md, session 59). Not with a descents
            // term: it reads the order at simulated time already.
            if (c.column_disorder->order_source.empty() && !needs_disorder)
                c.order_level = Disorder::from_json(model.at("disorder").at(setup).at(grid),
                                                    "model disorder " + setup + "/" + grid);
        }
        c.comm = CommModel::from_profile(model.at("machine"));
        c.exchange = ExchangeModel::from_profile(model.at("machine"));
        c.record_bytes = model.at("record_bytes").get<double>();
        c.cores = model.at("machine").at("cores").get<int>();
        if (model.contains("jitter")) {
            // Models before session 61 carry the square root alone, without "form".
            const auto &j = model.at("jitter");
            if (j.value("form", "sqrt") == "proportional")
                c.jitter = {JitterForm::proportional, j.at("k_proportional").get<double>()};
            else
                c.jitter = {JitterForm::sqrt, j.at("k_sqrt_s").get<double>()};
        }
        if (model.contains("time_sharing"))
            for (const auto &t : model.at("time_sharing")) {
                Costs::Sharing sh{t.at("overhead_s_per_step").get<double>(),
                                  t.at("overhead").get<double>(), 0.0};
                if (t.contains("overhead_fit") && !t.at("overhead_fit").is_null() &&
                    t.at("overhead_fit").value("significant", false)) {
                    sh.line_intercept =
                        t.at("overhead_fit").at("intercept_s_per_step").get<double>();
                    sh.per_compute = t.at("overhead_fit").at("per_compute").get<double>();
                    sh.line = true;
                }
                c.sharing[t.at("load").get<double>()] = sh;
            }
        if (model.contains("memory")) {
            const auto &mem = model.at("memory");
            // Per grid when the model has it (Cell+Sorted stores a copy, no pairs).
            const auto &m = mem.contains("grids") && mem.at("grids").contains(grid)
                                ? mem.at("grids").at(grid)
                                : mem;
            c.bytes_per_particle = m.at("bytes_per_particle").get<double>();
            c.bytes_per_interaction = m.at("bytes_per_interaction").get<double>();
            c.fixed_bytes = mem.at("fixed_bytes").get<double>();
        }
    } catch (const json::exception &e) {
        throw UsageError(std::string("model: ") + e.what());
    }
    return c;
}

double linear_law(const LinearFit &f, double n) {
    // p(n) = m n + r holds for ranks with field particles; none have no pairs.
    return n > 0 ? std::max(0.0, f.coefficient("m") * n + f.coefficient("r")) : 0.0;
}

struct RankStep {
    double field = 0, walls = 0, ghost = 0, exported = 0, exported_regression = 0, pairs = 0,
           pairs_regression = 0, interactions = 0, compute_s = 0, comm_s = 0, wait_s = 0,
           idle_s = 0;
    double order_factor = 1; // the rank's columns' memory order over the whole water's
};

// The time-sharing overhead at this many processes x threads (a factor on a shared core's
// summed compute, and seconds added to its step), and where it comes from.
struct SharingOverhead {
    double factor = 1.0, seconds_per_step = 0.0;
    const char *source = "";
    double per_compute = 0.0; // seconds added per second of the shared core's compute
    // Seconds added to a shared core's step of `compute` seconds (a fitted line is held at 0
    // where it would cross it below the shortest calibrated step).
    double added(double compute) const {
        return per_compute == 0 ? seconds_per_step
                                : std::max(0.0, seconds_per_step + per_compute * compute);
    }
};
SharingOverhead sharing_overhead(const Costs &c, int processes, const ExchangeSet *set,
                                 double gap_s) {
    if (processes <= c.cores)
        return {1.0, 0.0, "none (within the cores)"};
    const double load = static_cast<double>(processes) / c.cores;
    for (const auto &[l, o] : c.sharing)
        if (std::abs(l - load) < 1e-9)
            return c.sharing_ratio
                       ? SharingOverhead{o.ratio, 0.0, "time-shared calibration run (ratio)"}
                   : c.sharing_line && o.line
                       ? SharingOverhead{1.0, o.line_intercept,
                                         "time-shared calibration runs (seconds per step, a "
                                         "line in the shared core's compute)",
                                         o.per_compute}
                       : SharingOverhead{1.0, o.seconds_per_step,
                                         "time-shared calibration run (seconds per step)"};
    if (set)
        return {ExchangeModel::round_overhead(*set, gap_s), 0.0, "exchange benchmark"};
    return {1.0, 0.0, "none (no measurement at this load)"};
}

// The calibration's measured / fitted compute at the Froude time of simulated time t (held at
// the ends of the calibrated reach); 1 without a profile.
double profile_factor(const Costs &c, double t) {
    return c.profile.empty() ? 1.0 : interpolate(c.profile, t / std::sqrt(c.scale));
}

// The node of every rank as srun -N places P ranks on N nodes: in blocks, the first P mod N
// nodes one rank more.
std::vector<int> node_blocks(int P, int nodes) {
    std::vector<int> node(static_cast<std::size_t>(P));
    for (int n = 0, r = 0; n < nodes; ++n)
        for (int k = 0; k < P / nodes + (n < P % nodes ? 1 : 0); ++k)
            node[static_cast<std::size_t>(r++)] = n;
    return node;
}

// The first processing unit of every rank, each node's block placed as the launcher does.
std::vector<int> placement_of(int P, int nodes, int threads, int cores) {
    const std::vector<int> node = node_blocks(P, nodes);
    std::vector<int> pus;
    for (int n = 0; n < nodes; ++n) {
        const auto K = static_cast<int>(std::count(node.begin(), node.end(), n));
        for (int pu : launcher_placement(K, threads, cores))
            pus.push_back(pu);
    }
    return pus;
}

// One step of every rank at simulated time t, from the workload of the slabs.
// `order`: each rank's compute per interaction over the whole water's (ColumnDisorder), empty:
// 1 for every rank.
// `speed`: every compute time's factor (the host speed, times the drift within the run).
std::vector<RankStep> predict_step(const std::vector<SlabLoad> &loads, const WorkDensity &density,
                                   const Costs &c, int threads, int nodes, double t,
                                   const std::vector<double> &order, double speed, double &step_s,
                                   double *bubble_s = nullptr) {
    const double disorder = c.disorder ? c.disorder->at(t, c.delta) : 0.0;
    const int P = static_cast<int>(loads.size());
    // Each node places and time-shares its own block of ranks.
    const std::vector<int> node = node_blocks(P, nodes);
    std::vector<std::vector<int>> on_node(static_cast<std::size_t>(nodes));
    std::vector<int> local(static_cast<std::size_t>(P));
    for (int r = 0; r < P; ++r) {
        auto &block = on_node[static_cast<std::size_t>(node[static_cast<std::size_t>(r)])];
        local[static_cast<std::size_t>(r)] = static_cast<int>(block.size());
        block.push_back(r);
    }
    auto node_shared = [&](int n) {
        return static_cast<int>(on_node[static_cast<std::size_t>(n)].size()) * threads > c.cores;
    };
    auto pu = [&](int r) {
        return r < 0 || r >= P || node_shared(node[static_cast<std::size_t>(r)])
                   ? -1
                   : local[static_cast<std::size_t>(r)] * threads;
    };
    auto same_node = [&](int a, int b) {
        return node[static_cast<std::size_t>(a)] == node[static_cast<std::size_t>(b)];
    };
    const Link *inter = nodes > 1 ? c.comm.class_named("other_node") : nullptr;
    std::vector<RankStep> out(static_cast<std::size_t>(P));
    std::vector<double> compute, field;
    for (int r = 0; r < P; ++r) {
        const SlabLoad &l = loads[static_cast<std::size_t>(r)];
        RankStep &s = out[static_cast<std::size_t>(r)];
        s.field = l.field;
        s.walls = l.walls;
        s.ghost = l.ghost;
        s.exported = l.exported;
        s.exported_regression = linear_law(c.exports, l.field);
        // Pairs follow the flow: the trace's pairs per field particle at this Froude time (the
        // thesis' law, fitted over a whole run, is reported beside: it misses the time trend).
        s.pairs = density.pairs * l.field;
        s.pairs_regression = linear_law(c.pairs, l.field);
        s.interactions = density.interactions * l.field;
        std::vector<double> xm;
        for (const auto &t : c.cell_moves.terms)
            xm.push_back(t == "field"   ? l.field
                         : t == "walls" ? l.walls
                         : t == "ghost" ? l.ghost
                                        : 1.0);
        const double moves = std::max(0.0, c.cell_moves.predict(xm));
        const RankWork w{l.field,
                         l.walls,
                         l.ghost,
                         s.interactions,
                         moves,
                         s.interactions * disorder,
                         c.core_round_trip_s};
        std::vector<double> x;
        for (const auto &t : c.compute.terms)
            x.push_back(w.value(t));
        s.order_factor = order.empty() ? 1.0 : order[static_cast<std::size_t>(r)];
        s.compute_s =
            std::max(0.0, c.compute.predict(x)) * profile_factor(c, t) * s.order_factor * speed;
        compute.push_back(s.compute_s);
        field.push_back(s.field);
    }
    // Per node, the time-sharing bound of its block of ranks (0 where within the cores).
    auto node_step = [&](int n, const SharingOverhead &overhead) {
        const auto &block = on_node[static_cast<std::size_t>(n)];
        std::vector<double> bc, bf;
        for (int r : block) {
            bc.push_back(compute[static_cast<std::size_t>(r)]);
            bf.push_back(field[static_cast<std::size_t>(r)]);
        }
        const int K = static_cast<int>(block.size());
        const SharedStep s = time_shared_step(bc, bf, launcher_placement(K, threads, c.cores),
                                              threads, c.cores, overhead.factor);
        return s.step_s + (s.shared_core ? overhead.added(s.step_s) : 0.0);
    };
    // The compute since the shift before decides what a shift costs on this kind of machine
    // (exchange benchmark; ExchangeModel::app_shift_seconds): within the cores about half a
    // step before the migration and before the density refresh, a whole step since the last
    // ghosts for the ghosts, which follow the migration; above them a third of the step.
    // Above the core count the ranks take turns where the launcher put them, so a step spans
    // at least the busiest core's.
    double busy = 0;
    for (int n = 0; n < nodes; ++n) {
        if (node_shared(n)) {
            busy = std::max(busy, node_step(n, SharingOverhead{}));
            continue;
        }
        for (int r : on_node[static_cast<std::size_t>(n)])
            busy = std::max(busy, compute[static_cast<std::size_t>(r)]);
    }
    const double gap = busy / shifts_per_step;
    const int most_on_a_node = (P + nodes - 1) / nodes;
    const ExchangeSet *set =
        c.exchange.empty() ? nullptr : &c.exchange.set_for(most_on_a_node, threads, c.cores);
    const bool overlap_measured = set && set->has(ShiftMode::overlapped);
    // One message: across nodes the other_node class, within one the link of the two units.
    auto message = [&](int from, int to, double bytes) {
        return same_node(from, to) ? c.comm.seconds(pu(from), pu(to), bytes)
                                   : inter->fit.predict(bytes);
    };
    for (int r = 0; r < P && P > 1; ++r) {
        const SlabLoad &l = loads[static_cast<std::size_t>(r)];
        RankStep &s = out[static_cast<std::size_t>(r)];
        // Three exchanges (migration, ghosts, density), each an eastward then a westward shift
        // of a count and a payload; migration payloads are taken as empty (a few particles).
        const bool west = r > 0, east = r + 1 < P;
        const bool crosses = (west && !same_node(r, r - 1)) || (east && !same_node(r, r + 1));
        const double in_from_west = west ? loads[static_cast<std::size_t>(r - 1)].export_east : -1;
        const double in_from_east = east ? loads[static_cast<std::size_t>(r + 1)].export_west : -1;
        // The measured tables are by payload: the largest of this rank's four, in particles.
        const double most =
            std::max({l.export_east, l.export_west, in_from_west, in_from_east, 0.0});
        // `since`: the share of the busy compute between the shift before and this one. Within
        // the cores the ghosts, packed right after the migration, follow it (the exchange
        // benchmark's following table costs them; ExchangeModel::app_shift_seconds); the
        // migration and the density refresh come after the shares of the step the calibration
        // runs measured before them (segment_shares, per grid and thread count: about a third
        // and two thirds on the stored-list grids; on Cell+Sorted, whose sweep exchanges the
        // densities after all but the ghosts' neighbour columns' forces, nearly all and
        // nearly nothing), else half a step each.
        const auto share_before = [&](std::size_t segment) {
            return c.segment_shares ? (*c.segment_shares)[segment] : 1 / blocking_shifts_per_step;
        };
        auto exchange = [&](double per_particle, double since) {
            // One MPI_Sendrecv: both directions travel at once, it lasts the longer one.
            auto sendrecv = [&](int to, double out_b, int from, double in_b) {
                return std::max(to >= 0 && to < P ? message(r, to, out_b) : 0.0,
                                from >= 0 && from < P ? message(from, r, in_b) : 0.0);
            };
            auto shift = [&](double out_e, double in_w, double out_w, double in_e) {
                return sendrecv(r + 1, out_e, r - 1, in_w) + sendrecv(r - 1, out_w, r + 1, in_e);
            };
            const double hockney =
                shift(count_bytes, count_bytes, count_bytes, count_bytes) +
                shift(l.export_east * per_particle, std::max(0.0, in_from_west) * per_particle,
                      l.export_west * per_particle, std::max(0.0, in_from_east) * per_particle);
            if (!set)
                return hockney;
            // Above the cores the turn of a descheduled neighbour decides, as inline.
            const double since_any = set->load() > 1 ? gap : busy * since;
            const double measured =
                ExchangeModel::app_shift_seconds(*set, since_any, busy, most * per_particle);
            // A shift that leaves the node lasts at least its network messages.
            return crosses ? std::max(measured, hockney) : measured;
        };
        // --overlap: the ghost and density exchanges run behind the interior columns of a
        // stage (about a third of the step's compute, as the gap). Exposed stays what the
        // exchange benchmark measured of an overlapped shift with that much compute behind it
        // (exchange --overlapped), as sph --machine costs it; without such a measurement, what
        // no overlap hides, the rank taking in each received payload (its one-way Hockney
        // time), or the shift's cost beyond the compute behind it.
        auto overlapped = [&](double per_particle) {
            const double behind = s.compute_s / shifts_per_step;
            if (overlap_measured && !crosses)
                return ExchangeModel::shift_seconds(*set, behind, most * per_particle,
                                                    ShiftMode::overlapped);
            double exposed = 0;
            if (west)
                exposed += message(r - 1, r, in_from_west * per_particle);
            if (east)
                exposed += message(r + 1, r, in_from_east * per_particle);
            const double full =
                std::max(exchange(per_particle, 1 / blocking_shifts_per_step), exposed);
            return std::max(exposed, full - behind);
        };
        // (An --overlap run's migration follows its edge columns' forces and the kicks, as a
        // swept blocking run's follows the held columns' forces and the kicks.)
        s.comm_s =
            exchange(0.0, share_before(0)) +
            (c.overlap ? overlapped(c.record_bytes) + overlapped(density_bytes)
                       : exchange(c.record_bytes, 0.0) + exchange(density_bytes, share_before(2)));
    }
    // --time-sharing-overhead replay: one node, one-thread ranks bound round-robin: the step,
    // each rank's transfers and waits from the step replayed (who runs while whom waits).
    if (c.sharing_replay && nodes == 1 && threads == 1 && node_shared(0)) {
        if (!c.segment_shares)
            throw UsageError("--time-sharing-overhead replay (the default) needs the compute's "
                             "segment shares, which this model lacks: calibrate it again (session "
                             "39 or later) or pass --time-sharing-overhead per-step");
        const auto &sh = *c.segment_shares;
        std::vector<std::array<double, 3>> cpu;
        for (double x : compute)
            cpu.push_back({x * sh[0], x * sh[1], x * sh[2]});
        const ReplayedStep rep = replay_time_shared(cpu, c.cores, c.replay_slice_s);
        std::vector<int> core_of(compute.size());
        for (std::size_t r = 0; r < core_of.size(); ++r)
            core_of[r] = static_cast<int>(r) % c.cores;
        const double bubble = c.bubble_per_phi * sharing_bubble_phi(compute, core_of);
        step_s = rep.step_s * (1 + bubble);
        if (bubble_s)
            *bubble_s = rep.step_s * bubble;
        for (std::size_t r = 0; r < out.size(); ++r) {
            out[r].comm_s = rep.comm_s[r];
            out[r].wait_s = std::max(0.0, step_s - out[r].compute_s - out[r].comm_s);
            out[r].idle_s = out[r].field > 0 ? 0.0 : step_s;
        }
        return out;
    }
    // Within the cores the step lasts as long as the slowest rank's compute + communication,
    // each compute with its step-to-step jitter: the expected maximum, not the largest mean.
    // The exchanges are blocking: every rank's step lasts as long as the slowest. A core that
    // serves two busy ranks costs a little more than their summed compute (switches, a rank
    // waiting for a descheduled neighbour): the overhead the app's own time-shared calibration
    // runs measured at this load, else the exchange benchmark's round overhead. Above the cores
    // a rank waiting in a shift is descheduled and the others compute: the shifts' cost is
    // inside the time-sharing bound, not added to it.
    std::vector<double> mean, sd;
    double shared_step = 0;
    for (int n = 0; n < nodes; ++n) {
        if (node_shared(n)) {
            const int K = static_cast<int>(on_node[static_cast<std::size_t>(n)].size());
            shared_step =
                std::max(shared_step, node_step(n, sharing_overhead(c, K * threads, set, gap)));
            continue;
        }
        for (int r : on_node[static_cast<std::size_t>(n)]) {
            const auto &s = out[static_cast<std::size_t>(r)];
            mean.push_back(s.compute_s + s.comm_s);
            sd.push_back(jitter_sd(c.jitter, s.compute_s));
        }
    }
    step_s = std::max(shared_step, mean.empty() ? 0.0 : expected_max(mean, sd));
    for (auto &s : out) {
        s.wait_s = std::max(0.0, step_s - s.compute_s - s.comm_s);
        s.idle_s = s.field > 0 ? 0.0 : step_s;
    }
    return out;
}

// The band a prediction of `wall` seconds carries: +-wall_band_sds standard deviations of ln(time)
// of the calibration runs about their setup's level at this thread count (calibrate:
// level_scatter), null for a model without it or without a degree of freedom. It says how far one
// run on this host may land from the prediction when the model is right (model/NOTES.md, session
// 44).
json wall_band(const json &model, int threads, double wall) {
    if (!model.contains("level_scatter"))
        return nullptr;
    for (const auto &e : model.at("level_scatter").at("per_threads")) {
        if (e.at("threads").get<int>() != threads || e.at("dof").get<int>() < 1)
            continue;
        const double sd = e.at("log_sd").get<double>();
        return {{"log_sd", sd},
                {"dof", e.at("dof")},
                {"sds", wall_band_sds},
                {"low_s", wall * std::exp(-wall_band_sds * sd)},
                {"high_s", wall * std::exp(wall_band_sds * sd)}};
    }
    return nullptr;
}

} // namespace

ColumnWeights balance_weights(const json &model, const std::string &setup, const std::string &grid,
                              int threads) {
    const Costs c = costs_of(model, setup, grid, threads);
    if (!model.contains("traces") || !model["traces"].contains(setup))
        throw UsageError("the model has no workload trace of setup '" + setup +
                         "': calibrate with a " + setup + " run");
    const Trace trace = Trace::from_json(model["traces"][setup], "model trace " + setup);
    auto median = [](std::vector<double> v) {
        if (v.empty())
            return 0.0;
        std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
        return v[v.size() / 2];
    };
    const double per_fluid = median(trace.interactions_per_field);
    const double disorder =
        c.disorder ? median(c.disorder->per_interaction) : 0.0; // descents per interaction
    ColumnWeights w;
    w.fluid =
        c.compute.coefficient("owned") + per_fluid * (c.compute.coefficient("interactions") +
                                                      disorder * c.compute.coefficient("descents"));
    w.walls = c.compute.coefficient("owned") + c.compute.coefficient("walls");
    if (!(w.fluid > 0) || w.walls < 0)
        throw UsageError("the model's compute cost of grid " + grid + " at " +
                         std::to_string(threads) + " thread(s) gives a fluid particle " +
                         std::to_string(w.fluid) + " s and a wall particle " +
                         std::to_string(w.walls) + " s per step: expected > 0 and >= 0");
    w.source = "model: compute fit of " + grid + " at " + std::to_string(threads) + " thread(s), " +
               std::to_string(per_fluid) + " interactions per fluid particle";
    return w;
}

namespace {

// predict --host-speed: {"rule", "factor" on every compute time, "source"}. The model is at
// the median calibration run's speed. mean: the host's mean speed over the calibration runs of
// the predicted grid, thread count and setup (mean_factor.per_setup, session 76), else over
// every run (mean_factor.value, session 74 on), else 1; mean-pooled: over every run (session
// 75's rule); the source says which.
json host_speed_of(const json &model, const std::string &rule, const std::string &grid, int threads,
                   const std::string &setup) {
    if (rule != "mean" && rule != "mean-pooled" && rule != "median")
        throw UsageError("--host-speed '" + rule + "': expected mean, mean-pooled or median");
    json out{{"rule", rule}, {"factor", 1.0}};
    if (rule == "median") {
        out["source"] = "the median calibration run's speed (the model's reference)";
        return out;
    }
    const json gauge = model.value("speed_gauge", json(nullptr));
    const bool applied = gauge.is_object() && gauge.value("applied", false);
    if (!applied || !gauge.contains("mean_factor") || !gauge.at("mean_factor").contains("value")) {
        out["source"] = applied ? "the model has no speed_gauge.mean_factor (calibrated before "
                                  "session 74): at the median run's speed"
                                : "the calibration runs as measured (no speed gauge applied)";
        return out;
    }
    const json &mean = gauge.at("mean_factor");
    std::string key = "speed_gauge.mean_factor";
    double f = mean.at("value").get<double>();
    out["source"] = "the host's mean speed over every calibration run (speed_gauge.mean_factor)";
    if (rule == "mean") {
        out["source"] = "the host's mean speed over every calibration run (speed_gauge."
                        "mean_factor): the model has no calibration run of " +
                        grid + " at " + std::to_string(threads) + " thread(s) on " + setup +
                        (mean.contains("per_setup") ? "" : " (calibrated before session 76)");
        for (const auto &row : mean.value("per_setup", json::array()))
            if (row.at("grid") == grid && row.at("threads") == threads &&
                row.at("setup") == setup) {
                f = row.at("value").get<double>();
                key = "speed_gauge.mean_factor.per_setup " + grid + "/" + std::to_string(threads) +
                      "/" + setup;
                out["source"] = "the host's mean speed over the calibration runs of " + grid +
                                " at " + std::to_string(threads) + " thread(s) on " + setup +
                                " (speed_gauge.mean_factor.per_setup)";
            }
    }
    if (!std::isfinite(f) || f <= 0)
        throw UsageError("model " + key + " " + std::to_string(f) + ": expected a positive factor");
    out["factor"] = f;
    return out;
}

// predict --run-drift: the host's drift within a run (calibrate's speed_gauge.run_drift) at a
// time since the run's start, over the drift the calibration runs of the predicted grid,
// thread count and setup hold; 1 everywhere when off or when the model has none ("report"
// says which).
struct RunDrift {
    std::vector<double> edges, ln_profile;
    double held = 1;
    json report;
    double at(double t) const {
        if (ln_profile.empty())
            return 1.0;
        std::size_t b = 0;
        while (b + 1 < ln_profile.size() && t >= edges[b + 1])
            ++b;
        return std::exp(ln_profile[b]) / held;
    }
};

RunDrift run_drift_of(const json &model, const std::string &rule, const std::string &grid,
                      int threads, const std::string &setup) {
    if (rule != "on" && rule != "off")
        throw UsageError("--run-drift '" + rule + "': expected on or off");
    RunDrift d;
    d.report = {{"rule", rule}};
    if (rule == "off") {
        d.report["source"] = "predict --run-drift off: the host speed alone";
        return d;
    }
    const json gauge = model.value("speed_gauge", json(nullptr));
    const json drift = gauge.is_object() ? gauge.value("run_drift", json(nullptr)) : json(nullptr);
    if (!drift.is_object()) {
        d.report["source"] = "the model has no speed_gauge.run_drift (no speed gauge applied, "
                             "too few calibration runs spanning two time bins, or calibrated "
                             "before session 79): the host speed alone";
        return d;
    }
    for (const auto &row : drift.at("per_setup"))
        if (row.at("grid") == grid && row.at("threads") == threads && row.at("setup") == setup) {
            d.held = row.at("mean_drift").get<double>();
            d.edges = drift.at("edges_s").get<std::vector<double>>();
            d.ln_profile = drift.at("ln_profile").get<std::vector<double>>();
        }
    if (d.ln_profile.empty()) {
        d.report["source"] = "the model has no calibration run of " + grid + " at " +
                             std::to_string(threads) + " thread(s) on " + setup +
                             " within the cores: the host speed alone";
        return d;
    }
    if (!(d.held > 0) || d.edges.size() != d.ln_profile.size() || d.edges.front() != 0 ||
        std::adjacent_find(d.edges.begin(), d.edges.end(), std::greater_equal<>()) != d.edges.end())
        throw UsageError("model speed_gauge.run_drift: expected edges_s increasing from 0, an "
                         "ln_profile of the same length and a positive mean_drift");
    d.report["source"] = "the host's drift within runs (speed_gauge.run_drift) at each "
                         "interval's time since the run's start, over the drift the calibration "
                         "runs of " +
                         grid + " at " + std::to_string(threads) + " thread(s) on " + setup +
                         " hold (" + std::to_string(d.held) + ")";
    d.report["held_mean_drift"] = d.held;
    return d;
}

// A gauge reference (CPU seconds per sample, or null) at the predicted host speed.
json at_host_speed(const json &reference, double factor) {
    return reference.is_number() ? json(reference.get<double>() * factor) : reference;
}

} // namespace

json predict(const json &header, const json &model, const PredictRequest &req) {
    if (!model.contains("traces") || !model["traces"].contains(req.setup))
        throw UsageError("the model has no workload trace of setup '" + req.setup +
                         "': calibrate with a " + req.setup + " run");
    const Trace trace = Trace::from_json(model["traces"][req.setup], "model trace " + req.setup);
    const Costs costs = costs_of(model, req.setup, req.grid, req.threads);
    Costs c = costs;
    c.delta = req.delta;
    c.scale = req.scale;
    if (req.overlap && req.grid != "sorted")
        throw UsageError("--overlap needs --grid sorted (as sph --overlap), not --grid " +
                         req.grid);
    c.overlap = req.overlap;
    c.sharing_ratio = req.time_sharing_overhead == "ratio";
    c.sharing_line = req.time_sharing_overhead == "line";
    c.sharing_replay = req.time_sharing_overhead == "replay";
    c.replay_slice_s = req.replay_slice_s;
    if (req.untimed != "on" && req.untimed != "off")
        throw UsageError("--untimed '" + req.untimed + "': expected on or off");
    if (req.time_sharing_bubble != "on" && req.time_sharing_bubble != "off")
        throw UsageError("--time-sharing-bubble '" + req.time_sharing_bubble +
                         "': expected on or off");
    // The bubble was fitted against the replay at its default slice: at another slice the
    // replay's own step moves, and the bubble is not applied (the report says why).
    json bubble = {{"applied", false}};
    const json fitted_bubble = model.value("time_sharing_bubble", json(nullptr));
    if (!c.sharing_replay)
        bubble["reason"] = "no replay (--time-sharing-overhead " + req.time_sharing_overhead + ")";
    else if (req.time_sharing_bubble == "off")
        bubble["reason"] = "--time-sharing-bubble off";
    else if (fitted_bubble.is_null())
        bubble["reason"] = "the model has none: no calibration run time-shares two busy ranks on "
                           "every core";
    else {
        double slice = 0, k = 0, se = 0;
        try {
            slice = fitted_bubble.at("slice_s").get<double>();
            k = fitted_bubble.at("per_phi").get<double>();
            se = fitted_bubble.at("per_phi_se").get<double>();
        } catch (const json::exception &e) {
            throw UsageError(std::string("model time_sharing_bubble: ") + e.what());
        }
        if (!std::isfinite(k))
            throw UsageError("model time_sharing_bubble/per_phi is not a finite number");
        if (std::abs(req.replay_slice_s - slice) > 1e-12) {
            bubble["reason"] = "--replay-slice-ms differs from the slice it was fitted at";
        } else {
            c.bubble_per_phi = k;
            bubble["applied"] = true;
            bubble["per_phi"] = k;
            bubble["per_phi_se"] = se;
        }
    }
    const json host_speed = host_speed_of(model, req.host_speed, req.grid, req.threads, req.setup);
    c.host_speed = host_speed.at("factor").get<double>();
    const RunDrift run_drift = run_drift_of(model, req.run_drift, req.grid, req.threads, req.setup);
    if (req.cores > 0)
        c.cores = req.cores;
    const int max_ranks = *std::max_element(req.ranks.begin(), req.ranks.end());
    const Target probe =
        make_target(req.setup, req.grid, req.scale, req.delta, req.dt, max_ranks, req.threads);
    const std::int64_t steps =
        req.steps ? *req.steps
                  : static_cast<std::int64_t>(std::ceil(*req.end_time / req.dt - 1e-9));
    // Refuse up front when the trace or the memory-order record is too short, naming the time
    // needed.
    (void)histogram_at(trace,
                       source_time(static_cast<double>(steps) * req.dt, trace.scale, req.scale));
    if (c.disorder)
        (void)c.disorder->at(static_cast<double>(steps) * req.dt, req.delta);
    if (req.rank_disorder != "columns" && req.rank_disorder != "none")
        throw UsageError("--rank-disorder '" + req.rank_disorder + "': expected columns or none");
    if (req.rank_disorder == "none")
        c.column_disorder.reset();
    if (!(req.memory_order_carry >= 0 && req.memory_order_carry <= 1))
        throw UsageError("--memory-order-carry " + std::to_string(req.memory_order_carry) +
                         ": expected a share from 0 to 1");
    if (req.memory_order_time != "simulated" && req.memory_order_time != "froude" &&
        req.memory_order_time != "columns")
        throw UsageError("--memory-order-time '" + req.memory_order_time +
                         "': expected simulated, froude or columns");
    // Only with the Froude-time profile: its cost was measured at the whole water's order at
    // that Froude time (SlabOrder::all), from which each slab is carried.
    if (req.memory_order_time != "simulated" || !c.column_disorder || c.profile.empty())
        c.order_level.reset();
    if (c.order_level)
        try {
            (void)c.order_level->at(static_cast<double>(steps) * req.dt, req.delta);
        } catch (const UsageError &e) {
            throw UsageError(std::string(e.what()) +
                             ", or predict with --memory-order-time froude");
        }
    if (c.column_disorder)
        (void)c.column_disorder->rank_factors(static_cast<double>(steps) * req.dt, req.scale,
                                              probe.cell_size, probe.tank_length, probe.columns,
                                              sph::equal_cuts(1, probe.columns));
    if (const double need = static_cast<double>(steps) * req.dt / std::sqrt(req.scale);
        !c.profile.empty() && need > c.profile_end * (1 + 1e-9))
        throw UsageError("the calibration's " + req.grid + " runs of " + req.setup +
                         " reach Froude time " + std::to_string(c.profile_end) +
                         " s (t / sqrt(scale)); " + std::to_string(steps) + " steps at scale " +
                         std::to_string(req.scale) + " need " + std::to_string(need) +
                         " s: calibrate with longer " + req.grid + " runs");

    if (req.nodes < 1)
        throw UsageError("--nodes " + std::to_string(req.nodes) + " is not a positive node count");
    for (int P : req.ranks)
        if (P < req.nodes)
            throw UsageError("--ranks " + std::to_string(P) + " is fewer than --nodes " +
                             std::to_string(req.nodes) + ": every node needs a rank");
    if (req.nodes > 1 && !c.comm.class_named("other_node"))
        throw UsageError("--nodes " + std::to_string(req.nodes) +
                         " needs the machine's other_node class, which the model's machine "
                         "profile lacks: run scripts/slurm/pingpong-nodes.sbatch on two or more "
                         "nodes, then calibrate again");
    json out = header;
    out["request"] = {{"setup", req.setup},     {"grid", req.grid},
                      {"scale", req.scale},     {"delta", req.delta},
                      {"dt", req.dt},           {"steps", steps},
                      {"threads", req.threads}, {"interval", req.interval},
                      {"cores", c.cores},       {"ranks", req.ranks},
                      {"nodes", req.nodes},     {"overlap", req.overlap}};
    out["model_source"] = {
        {"git_commit", model.value("git_commit", "")},
        {"timestamp", model.value("timestamp", "")},
        {"trace", trace.source},
        {"trace_scale", trace.scale},
        {"trace_delta", trace.delta},
        {"jitter_form", to_string(c.jitter.form)},
        {c.jitter.form == JitterForm::sqrt ? "jitter_k_sqrt_s" : "jitter_k_proportional",
         c.jitter.k},
        {"compute_time_profile", c.profile.empty() ? "none" : "froude"},
        {"core_round_trip_s", c.core_round_trip.is_null() ? json(nullptr) : c.core_round_trip},
        {"rank_disorder", c.column_disorder ? "columns" : "none"},
        {"memory_order_time", c.order_level ? "simulated"
                              : c.column_disorder
                                  ? (req.memory_order_time == "columns" ? "columns" : "froude")
                                  : "none"}};
    if (c.order_level)
        out["model_source"]["memory_order_carry"] = req.memory_order_carry;
    if (c.column_disorder)
        out["model_source"]["rank_disorder_source"] = c.column_disorder->source;
    out["fluid_particles"] = probe.fluid_particles;
    out["request"]["time_sharing_overhead"] = req.time_sharing_overhead;
    out["host_speed"] = host_speed;
    out["run_drift"] = run_drift.report;
    out["time_sharing_bubble"] = bubble;
    if (c.sharing_replay)
        out["request"]["replay_slice_s"] = req.replay_slice_s;
    out["request"]["decompositions"] = req.decompositions;
    out["request"]["balance_weights"] = {
        {"fluid", req.weights.fluid}, {"walls", req.weights.walls}, {"source", req.weights.source}};
    json configs = json::array();
    for (const std::string &dec : req.decompositions)
        for (int P : req.ranks) {
            const Target tgt =
                make_target(req.setup, req.grid, req.scale, req.delta, req.dt, P, req.threads);
            // The slabs: equal ones, or balanced ones re-cut by the app's rule (sph/balance.hpp)
            // from the workload at each re-cut step, sph's own schedule: step 0, then every N
            // steps.
            const bool balanced = dec == "balanced";
            const int every = req.rebalance_every > 0 ? req.rebalance_every : req.interval;
            std::vector<int> cuts = sph::equal_cuts(P, tgt.columns);
            std::int64_t next_cut = 0;
            json rebalances = json::array();
            double rebalance_total = 0;
            auto recut_at = [&](std::int64_t step) {
                const double t = static_cast<double>(step) * req.dt;
                const auto cols =
                    rescale_columns(histogram_at(trace, source_time(t, trace.scale, req.scale)),
                                    trace.cell_size, trace.tank_length, tgt.cell_size,
                                    tgt.tank_length, tgt.columns, tgt.fluid_particles);
                std::vector<double> cost(cols.size()), count(cols.size());
                for (std::size_t k = 0; k < cols.size(); ++k) {
                    cost[k] = req.weights.fluid * cols[k] + req.weights.walls * tgt.wall_columns[k];
                    count[k] = cols[k] + tgt.wall_columns[k];
                }
                const auto next = sph::balanced_cuts(cost, P);
                // Particles cross one boundary per hop: those between a cut's old and new column.
                double crossings = 0, most = 0;
                for (std::size_t b = 1; b + 1 < next.size(); ++b) {
                    const auto lo = std::min(cuts[b], next[b]), hi = std::max(cuts[b], next[b]);
                    const double n = std::accumulate(count.begin() + lo, count.begin() + hi, 0.0);
                    crossings += n;
                    most = std::max(most, n);
                }
                // A fresh run's first cut moves nothing (every rank builds the whole state).
                // Over several nodes a moved cut may cross between them: the slower link.
                const int per_node = (P + req.nodes - 1) / req.nodes;
                const double secs =
                    step == 0 || P == 1
                        ? 0.0
                        : std::max(c.comm.sendrecv_seconds(
                                       0, per_node * req.threads > c.cores ? -1 : req.threads,
                                       most * c.record_bytes, -1, -1),
                                   req.nodes > 1 ? c.comm.class_named("other_node")
                                                       ->fit.predict(most * c.record_bytes)
                                                 : 0.0);
                rebalance_total += secs;
                const double mean = std::accumulate(cost.begin(), cost.end(), 0.0) / P;
                rebalances.push_back(
                    {{"step", step},
                     {"cuts", next},
                     {"moved_particles", step == 0 ? 0.0 : crossings},
                     {"rebalance_s", secs},
                     {"imbalance_after", mean > 0 ? sph::max_slab_cost(cost, next) / mean : 1.0}});
                cuts = next;
            };
            json intervals = json::array();
            std::vector<RankStep> tot(static_cast<std::size_t>(P)); // sums over the run's steps
            // Largest stored particle count and interaction count of each rank at any sample.
            std::vector<double> peak_particles(static_cast<std::size_t>(P), 0.0),
                peak_interactions(static_cast<std::size_t>(P), 0.0);
            double wall = 0, idle_onset_step = -1;
            double last_interval_s = 0, drift_compute = 0, drift_weight = 0, bubble_total = 0;
            // The wall time no phase timer holds, per step (the run's own bookkeeping).
            const double untimed_step =
                req.untimed == "on" ? untimed_s_per_step_for(model, P, req.threads) : 0.0;
            for (std::int64_t s0 = 0; s0 < steps; s0 += req.interval) {
                const std::int64_t s1 = std::min<std::int64_t>(steps, s0 + req.interval);
                const double n = static_cast<double>(s1 - s0);
                // The host's drift at the interval's middle (its length: the last interval's).
                const double drift = run_drift.at(wall + last_interval_s / 2);
                std::vector<RankStep> mean(static_cast<std::size_t>(P));
                for (auto &m : mean)
                    m.order_factor = 0; // a mean over the samples below
                std::vector<double> order_descents(static_cast<std::size_t>(P), 0.0),
                    order_weight(static_cast<std::size_t>(P), 0.0);
                double step_mean = 0;
                for (int k = 0; k < samples_per_interval; ++k) {
                    const double at_step =
                        static_cast<double>(s0) + (k + 0.5) * n / samples_per_interval;
                    while (balanced && static_cast<double>(next_cut) <= at_step) {
                        recut_at(next_cut);
                        next_cut = next_cut == 0 ? every : next_cut + every;
                    }
                    const double t = req.dt * at_step;
                    const double ts = source_time(t, trace.scale, req.scale);
                    const auto src = histogram_at(trace, ts);
                    const auto cols =
                        rescale_columns(src, trace.cell_size, trace.tank_length, tgt.cell_size,
                                        tgt.tank_length, tgt.columns, tgt.fluid_particles);
                    double step_s = 0, bubble_s = 0;
                    std::optional<ColumnDisorder::SlabOrder> slabs;
                    // columns: each column's order read at the target's simulated time (the
                    // record at the same time, the columns at their relative place): a column's
                    // descents follow simulated time as the whole water's do, back columns
                    // too (model/NOTES.md, session 91). froude: at its Froude time.
                    if (c.column_disorder)
                        slabs = c.column_disorder->slab_order(
                            t,
                            req.memory_order_time == "columns" && !balanced
                                ? c.column_disorder->scale
                                : req.scale,
                            tgt.cell_size, tgt.tank_length, tgt.columns, cuts);
                    // Equal slabs only: a balanced run's re-cuts refile its particles, and it
                    // keeps its order (0.12 descents per interaction at 0.15 s against 0.31),
                    // which the Froude-time record matches better (validate's memory-order
                    // term: median +0.5 %).
                    // The order the run counts is carried whole (validate's memory-order
                    // term); its cost follows a share of that carry (--memory-order-carry,
                    // validate's cost term: model/NOTES.md, session 73).
                    auto priced = slabs;
                    if (slabs && c.order_level && !balanced) {
                        const double whole = c.order_level->at(t, c.delta);
                        priced = ColumnDisorder::at_whole_order(
                            *slabs, slabs->all + req.memory_order_carry * (whole - slabs->all));
                        slabs = ColumnDisorder::at_whole_order(*slabs, whole);
                    }
                    const std::vector<double> order =
                        priced ? c.column_disorder->factors(*priced) : std::vector<double>{};
                    const auto ranks = predict_step(
                        recut(cols, tgt.wall_columns, cuts), density_at(trace, ts), c, req.threads,
                        req.nodes, t, order, c.host_speed * drift, step_s, &bubble_s);
                    step_mean += step_s / samples_per_interval;
                    bubble_total += bubble_s * n / samples_per_interval;
                    for (std::size_t r = 0; r < ranks.size(); ++r) {
                        auto &m = mean[r];
                        const auto &v = ranks[r];
                        // The rank's descents per interaction, weighted by its interactions.
                        if (slabs && r < slabs->slabs.size() && slabs->slabs[r]) {
                            order_descents[r] += *slabs->slabs[r] * v.interactions;
                            order_weight[r] += v.interactions;
                        }
                        peak_particles[r] =
                            std::max(peak_particles[r], v.field + v.walls + v.ghost);
                        peak_interactions[r] = std::max(peak_interactions[r], v.interactions);
                        for (auto [dst, src_v] : {std::pair{&m.field, v.field},
                                                  {&m.walls, v.walls},
                                                  {&m.ghost, v.ghost},
                                                  {&m.exported, v.exported},
                                                  {&m.exported_regression, v.exported_regression},
                                                  {&m.pairs, v.pairs},
                                                  {&m.pairs_regression, v.pairs_regression},
                                                  {&m.interactions, v.interactions},
                                                  {&m.compute_s, v.compute_s},
                                                  {&m.order_factor, v.order_factor},
                                                  {&m.comm_s, v.comm_s},
                                                  {&m.wait_s, v.wait_s},
                                                  {&m.idle_s, v.idle_s}})
                            *dst += src_v / samples_per_interval;
                    }
                }
                json jr = json::array();
                bool all_busy = true;
                for (std::size_t r = 0; r < mean.size(); ++r) {
                    const auto &m = mean[r];
                    all_busy = all_busy && m.field >= 1;
                    jr.push_back({{"field", m.field},
                                  {"walls", m.walls},
                                  {"ghost", m.ghost},
                                  {"exported", m.exported},
                                  {"exported_regression", m.exported_regression},
                                  {"pairs", m.pairs},
                                  {"pairs_regression", m.pairs_regression},
                                  {"interactions", m.interactions},
                                  {"memory_order_factor", m.order_factor},
                                  {"compute_s", m.compute_s * n},
                                  {"comm_s", m.comm_s * n},
                                  {"wait_s", m.wait_s * n},
                                  {"idle_s", m.idle_s * n}});
                    // The memory order the factor came from, where it is the grid's own
                    // descents (validate compares it with the run's): Cell+List's line reads
                    // Cell+Table's, which a list run does not count.
                    if (order_weight[r] > 0 && c.column_disorder->order_source.empty())
                        jr.back()["descents_per_interaction"] = order_descents[r] / order_weight[r];
                    RankStep &t = tot[r];
                    t.compute_s += m.compute_s * n;
                    t.comm_s += m.comm_s * n;
                    t.wait_s += m.wait_s * n;
                    t.idle_s += m.idle_s * n;
                    t.pairs += m.pairs * n;
                    t.pairs_regression += m.pairs_regression * n;
                    t.exported += m.exported * n;
                }
                if (balanced && all_busy && idle_onset_step < 0)
                    idle_onset_step = static_cast<double>(s0);
                step_mean += untimed_step;
                wall += step_mean * n;
                last_interval_s = step_mean * n;
                for (const auto &m : mean) {
                    drift_compute += drift * m.compute_s * n;
                    drift_weight += m.compute_s * n;
                }
                intervals.push_back({{"step", s1},
                                     {"time_s", static_cast<double>(s1) * req.dt},
                                     {"wall_s", step_mean * n},
                                     {"untimed_s", untimed_step * n},
                                     {"ranks", jr}});
            }
            json first_busy = nullptr;
            if (!balanced) {
                const IdleOnset o =
                    idle_onset(trace, tgt, sph::equal_cuts(P, tgt.columns), req.dt, steps);
                idle_onset_step = o.all ? static_cast<double>(*o.all) : -1.0;
                first_busy = json::array();
                for (const auto &f : o.per_rank)
                    first_busy.push_back(f ? json(*f) : json(nullptr));
            }
            json per_rank = json::array();
            double compute = 0, comm = 0, wait = 0, idle = 0;
            for (int r = 0; r < P; ++r) {
                const RankStep &t = tot[static_cast<std::size_t>(r)];
                const auto per_step = [&](double v) { return v / static_cast<double>(steps); };
                per_rank.push_back({{"compute_s", t.compute_s},
                                    {"comm_s", t.comm_s},
                                    {"wait_s", t.wait_s},
                                    {"idle_s", t.idle_s},
                                    {"pairs_per_step", per_step(t.pairs)},
                                    {"pairs_regression_per_step", per_step(t.pairs_regression)},
                                    {"exported_per_step", per_step(t.exported)}});
                compute += t.compute_s;
                comm += t.comm_s;
                wait += t.wait_s;
                idle += t.idle_s;
            }
            json memory = nullptr;
            if (c.bytes_per_particle > 0) {
                json rss = json::array();
                double worst = 0, worst_thesis = 0, total = 0;
                for (std::size_t r = 0; r < peak_particles.size(); ++r) {
                    const double n = peak_particles[r];
                    const double b = c.fixed_bytes + c.bytes_per_particle * n +
                                     c.bytes_per_interaction * peak_interactions[r];
                    const double thesis =
                        2 * n * c.bytes_per_particle + n * c.bytes_per_particle * thesis_k / 2;
                    rss.push_back(b);
                    total += b;
                    worst = std::max(worst, b);
                    worst_thesis = std::max(worst_thesis, thesis);
                }
                memory = {{"peak_rss_bytes_per_rank", rss},
                          {"peak_rss_bytes_max_rank", worst},
                          {"thesis_bound_bytes_max_rank", worst_thesis},
                          {"peak_rss_bytes_total", total}};
            }
            wall += rebalance_total;
            const double run_drift_mean = drift_weight > 0 ? drift_compute / drift_weight : 1.0;
            const int per_node = (P + req.nodes - 1) / req.nodes;
            configs.push_back(
                {{"ranks", P},
                 {"decomposition", dec},
                 {"rebalance_s", rebalance_total},
                 {"rebalances", balanced ? rebalances : json(nullptr)},
                 {"memory", memory},
                 {"threads", req.threads},
                 {"nodes", req.nodes},
                 {"ranks_per_node_max", per_node},
                 {"oversubscribed", per_node * req.threads > c.cores},
                 {"placement_pus", placement_of(P, req.nodes, req.threads, c.cores)},
                 {"time_sharing_source",
                  c.sharing_replay && req.nodes == 1 && req.threads == 1 && P > c.cores
                      ? "the step replayed (replay_time_shared)"
                      : sharing_overhead(c, per_node * req.threads,
                                         c.exchange.empty()
                                             ? nullptr
                                             : &c.exchange.set_for(per_node, req.threads, c.cores),
                                         0)
                            .source},
                 {"wall_s", wall},
                 // The host speed the prediction is at (calibrate's speed gauge; null: the
                 // calibration runs as measured).
                 // With the run's drift: its mean over the run's compute.
                 {"speed_gauge_reference_cpu_s",
                  at_host_speed(gauge_reference_for(model.value("speed_gauge", json(nullptr)),
                                                    req.grid, req.threads),
                                c.host_speed * run_drift_mean)},
                 {"run_drift_mean_factor", run_drift_mean},
                 // The replay's bubble added to the wall (0: none, or not applied).
                 {"time_sharing_bubble_s", bubble_total},
                 // The wall time no phase timer holds, added to the wall (--untimed).
                 {"untimed_s", untimed_step * static_cast<double>(steps)},
                 // How far a run's time follows its gauge (calibrate's elasticity; 1: whole).
                 {"speed_gauge_elasticity",
                  gauge_elasticity_for(model.value("speed_gauge", json(nullptr)))},
                 {"wall_band", wall_band(model, req.threads, wall)},
                 {"totals",
                  {{"compute_s", compute}, {"comm_s", comm}, {"wait_s", wait}, {"idle_s", idle}}},
                 {"first_step_all_ranks_busy",
                  idle_onset_step >= 0 ? json(static_cast<std::int64_t>(idle_onset_step))
                                       : json(nullptr)},
                 {"first_step_busy_per_rank", first_busy},
                 {"idle_fraction", wall > 0 ? idle / (P * wall) : 0.0},
                 {"per_rank", per_rank},
                 {"intervals", intervals}});
        }
    // Speed-up and efficiency against the smallest rank count predicted.
    const double base =
        configs.front()["wall_s"].get<double>() * configs.front()["ranks"].get<double>();
    for (auto &cfg : configs) {
        const double P = cfg["ranks"].get<double>();
        const double w = cfg["wall_s"].get<double>();
        cfg["speedup"] = base / configs.front()["ranks"].get<double>() / w;
        cfg["efficiency"] = base / (P * w);
    }
    out["configurations"] = configs;
    return out;
}

} // namespace sphperf::model
