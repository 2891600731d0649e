#pragma once
// The SPH runtime model: calibrate from SPH reports and a machine profile, predict the wall time
// per rank count with its breakdown (compute, communication, wait, idle), and validate a
// prediction against measured reports. Each function returns the JSON document it describes.
#include "sphperf/model/comm_model.hpp"
#include "sphperf/model/fit.hpp"
#include "sphperf/model/jitter.hpp"
#include "sphperf/model/placement.hpp"
#include "sphperf/model/sph_run.hpp"
#include "sphperf/model/workload.hpp"

#include <nlohmann/json.hpp>

#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace sphperf::model {

// Flops and bytes per neighbour interaction per step, counted from sph/physics.hpp, kernel.hpp
// and grid_impl.hpp (model/NOTES.md shows the count). Bytes assume no cache reuse, as the
// thesis' 56 bytes per pair did: an upper bound on memory traffic.
struct InteractionCost {
    const char *stage;
    double flops, bytes;
};
inline constexpr InteractionCost interaction_costs[] = {
    {"neighbour search (2.86 candidates per interaction)", 14.3, 91.5},
    {"continuity (at the middle of the drift)", 35.3, 44.0},
    {"momentum", 43.8, 60.0},
    {"shepard filter (every 30 steps)", 0.8, 1.5},
};
// Cell+Sorted (sph/src/sorted.cpp): no search and no stored pairs; each pass packs a
// particle's in-range candidates of the three column ranges (2.15 candidates per interaction:
// 3 x 2.25 cells against a disc of one cell radius; distance and masks, 7 flops each, reading
// 16 bytes of x, y) and runs the branch-free term over the packed pairs only, in single
// precision (sph PairReal): the pack writes and the term reads a 4-byte index and 4-byte
// dx, dy; the term reads 4-byte vx, vy (density) or vx, vy, rho, P/rho^2 (momentum) and the
// 8-byte mass. Bytes: 34.4 + 12 + 4 + 8 + 8 + 8 = 74.4 and 34.4 + 12 + 4 + 8 + 16 + 8 = 82.4
// (98.4 and 114.4 with double pair terms, before session 67).
inline constexpr InteractionCost sorted_interaction_costs[] = {
    {"continuity: pack (2.15 candidates per interaction), term per pair", 61.05, 74.4},
    {"momentum: pack, term per pair", 75.05, 82.4},
    {"shepard filter (every 30 steps)", 2.9, 2.3},
};
// The table of a grid scheme.
inline std::span<const InteractionCost> interaction_costs_of(std::string_view grid) {
    if (grid == "sorted")
        return sorted_interaction_costs;
    return interaction_costs;
}

// The cost of one rank's step from its work counts; the terms the fit may use.
inline constexpr const char *cost_terms[] = {"const",    "interactions",    "owned",
                                             "walls",    "ghost",           "cell_moves",
                                             "descents", "core_round_trips"};
struct RankWork {
    double field = 0, walls = 0, ghost = 0, interactions = 0, cell_moves = 0;
    double descents = 0; // the id sort's work (list and table), see Disorder
    // The mean round trip of a cache line between the rank's threads 0 and 1 (sph's core
    // latency gauge), seconds: the term core_round_trips costs it, its coefficient the round
    // trips a step waits on (0: one thread, or not measured).
    double core_round_trip_s = 0;
    double value(const std::string &term) const;
};

// The compute cost of one calibrated entry (`model.json` `compute[i]`) for a setup: its
// coefficients at the setup's own run level when the calibration ran that setup.
LinearFit compute_cost_of(const nlohmann::json &entry, const std::string &setup);

// How the compute cost's terms are chosen (model/NOTES.md, "Choosing the cost terms").
//   levelled_one_se: one cost level per setup in the fit and in its cross-validation, and the
//     smallest set of terms within one standard error of the best held-out score (session 13);
//   pooled_one_percent: one fit pooling the setups, a term kept when it lowers the held-out
//     error by 1 % (sessions 9-12), kept to report beside it.
enum class TermSelection { levelled_one_se, levelled_best, pooled_one_percent };
// What the term selection's cross-validation holds out at a time. run: one calibration run
// (sessions 13 on); configuration: every repeat of one configuration (setup, scale, ranks ...)
// where its setup ran two or more configurations, else one run, so that a set of terms is
// scored on a scale or rank count it did not see, as a prediction is.
enum class CvHoldOut { run, configuration };
// How the cost of an interaction changes as a flow evolves. froude: a profile over Froude time
// (t / sqrt(scale)) of measured over fitted compute per setup, from the calibration runs (a
// robust quadratic; froude_windowed: a moving ratio, sessions 16-41), and no time-varying term
// in the fit; none: the fit alone (with the memory-order term "descents" read
// at simulated time, when selected).
enum class TimeProfile { froude, froude_windowed, none };
// How the cost fit weighs its points. absolute: seconds per step, so the runs with the longest
// steps dominate; relative: each point divided by its run's median step, so a small-scale run
// counts as much as a large one and the held-out error is relative, as the targets are.
enum class FitWeights { absolute, relative };
// How a setup's cost level is set from its calibration runs (measured / fitted compute per run).
//   fastest_repeat: per configuration (scale, ranks, threads, steps...) the fastest of its
//     repeated runs, then the median over configurations; the time profile carries the shape
//     over Froude time only (each run's intervals at the run's own level) (session 43);
//   median: the median run, the profile as for fastest_repeat;
//   pooled: the median run, but the time profile carries the pooled level of all runs, which
//     overrides it (sessions 16-42, and the default again since session 45: a sum of step
//     times pays the mean, and on the VM's Intel host the fastest repeat sat below it).
enum class RunLevelRule { fastest_repeat, median, pooled };
// How calibration uses the runs' speed gauge (sph --speed-gauge-every). interval: each
// interval's times divided by the host's speed factor around it (the compute-weighted median of
// the gauge over +-1 interval, session 54); interval_mean: the same with the window's
// compute-weighted mean (sessions 51-53), which one disturbed gauge sample moves; run: one
// factor per run (session 50, and the default again since session 85: the reference is made of
// runs' whole gauges, and an interval's median of few skewed samples sits below its run's, so
// per interval the calibration runs came out 1.2-2.1 % dearer than per run and the model high);
// off: the runs as measured.
enum class SpeedGauge { interval, interval_mean, run, off };
// Intervals each side pooled into an interval's gauge (--speed-gauge interval). Chosen in
// session 51 from the calibration runs alone: between repeated rounds of one configuration
// the shape of the cost over the run differed by 11.1 % (sd of ln, level removed) with one
// factor per run, 9.5 / 7.8 / 7.9 / 8.3 % with windows of 0 / 1 / 2 / 4 intervals.
constexpr int speed_gauge_half_window = 1;
// Which runs' median gauge is the reference speed. pooled: every run's median (sessions 50-58,
// the default); grid: each grid and thread count's own runs' median, so a grid's model is at its
// own runs' median speed. On the 512-bit build (session 58) the gauge read 3-9 % slower in
// Cell+Table runs than in Cell+Sorted runs made in alternation, so pooled puts Cell+Sorted's
// runs a few per cent above their own speed; but replayed on session 57's and earlier stored
// jobs (256-bit) grid raised the max in 7 of 8 quiet ones (model/NOTES.md, session 58).
enum class GaugeReference { grid, pooled };
// How far the runs' times follow the gauge. one (the default): divided by the factor itself
// (sessions 50-74); fitted: by the factor raised to the elasticity beta of the compute per
// interaction to the gauge, estimated from the calibration runs themselves, between the
// repeats of a configuration where there are repeats (gauge_elasticity_between_repeats), else
// within runs (gauge_elasticity); both reported either way. Within runs it read 0.38-0.88 in
// session 70's ten jobs, and fitted on it made the wall median worse in six of them; that
// estimate is flattened by the gauge sample's noise: between repeats it reads 0.92 (Cell+List
// and Cell+Table) and 1.01 (Cell+Sorted) pooled over sixteen jobs (model/NOTES.md, session 74).
enum class GaugeElasticity { fitted, one };
// The memory order's cost line (ColumnDisorder) over times put at one speed within each run by
// the speed gauge around every interval (interval, sessions 91-92), or at the run's speed
// alone as every other fit (run), or by each rank-interval's own kernel time per interaction
// (kernel), or by the interval gauge and, where that line is unusable, the kernel (session 93).
enum class OrderLineGauge { interval, run, kernel, interval_or_kernel };
struct CalibrateOptions {
    bool allow_other_host = false;
    TermSelection term_selection = TermSelection::levelled_one_se;
    TimeProfile time_profile = TimeProfile::froude;
    FitWeights fit_weights = FitWeights::relative;
    RunLevelRule run_level = RunLevelRule::pooled;
    // Put every calibration run at one host speed by its speed gauge (speed_normalise): one
    // factor per run since session 85 (per interval in sessions 51-84; model/NOTES.md).
    SpeedGauge speed_gauge = SpeedGauge::run;
    GaugeReference gauge_reference = GaugeReference::pooled;
    GaugeElasticity gauge_elasticity = GaugeElasticity::one;
    OrderLineGauge order_line_gauge = OrderLineGauge::interval_or_kernel;
    // Offer the cost term `walls` (every wall particle of a rank) to the term selection, as
    // sessions 1-50 did; session 51 measured that a rank's dry walls cost nothing (calibrate.cpp).
    bool walls_term = false;
    // The jitter's form (jitter.hpp): chosen by leave-one-run-out cross-validation of the
    // calibration runs' waits (nullopt, the default since session 61), or this one.
    std::optional<JitterForm> jitter_form;
    // Refuse a term set that prices one item (an owned or ghost particle, a cell move, a wall)
    // above a fluid particle's interactions: a ghost or a move is part of a particle's work. In
    // Cell+List and Cell+Table runs cell moves are the ghosts (re-filed every step), absent
    // from the 1-rank runs: a fit at 6-11 us each priced that contrast, not the item, and put
    // 3-4 rank runs 24-162 % high (model/NOTES.md, sessions 33 and 73). Since session 73.
    bool bound_item_costs = true;
    CvHoldOut cv_hold_out = CvHoldOut::run;
};
// The speed gauge's normalisation (session 50): each run's gauge CPU seconds per sample over
// the runs' median is the host's speed factor during that run, and every time the run measured
// is divided by it, so the fit sees the runs at one speed (the median run's). With
// SpeedGauge::interval each interval's times are divided by the factor of the gauge around it
// (SphRun::interval_gauges_s) instead, so a host that sped up or slowed down within a run does
// not bend the cost's shape over the flow. Applied unless `mode` is off, when every run carries
// gauge samples; returns {"applied", "mode", "reason" or "reference_cpu_s_per_sample", "runs":
// [{path, gauge_cpu_s_per_sample, factor (the run's, compute-weighted), interval_factors (with
// interval)}], "log_sd" (standard deviation of ln factor over the runs), "mean_factor":
// {value: the runs' compute as measured over their compute at the reference, the host's mean
// speed over the calibration against the median run's; reported, not applied}}. With
// GaugeReference::grid each run's factor is over the median of its grid and thread count's runs
// ("references": [{grid, threads, reference_cpu_s_per_sample, runs}]); the pooled median stays
// in "reference_cpu_s_per_sample".
// With GaugeElasticity::fitted the factors are raised to the elasticity estimated from these
// runs, between repeats where there are repeats (gauge_elasticity_between_repeats), else
// within runs (gauge_elasticity) ("elasticity": the estimate within runs, "between_repeats",
// and the exponent used: 1 where the estimate's standard error is above max_elasticity_se or
// there is none); each run row then
// carries "applied_factor" (and "interval_applied_factors") beside the gauge's own "factor".
// `cores`: the node's, so that runs above them (their timers hold the time they were
// descheduled) stay out of the estimate; 0: none left out.
// The host's speed drift within runs (model/NOTES.md, session 79): the runs' speed gauge as a
// level per run plus a profile over the time since the run started, fitted on the busy
// rank-intervals of runs within `cores` (0: all); {"edges_s", "ln_profile", "runs",
// "per_setup": [{"grid", "threads", "setup", "mean_drift"}], "method"}, or null with fewer
// than two runs spanning two time bins. speed_normalise puts it in "run_drift".
nlohmann::json run_drift(const std::vector<SphRun> &runs, int cores);
// The pipeline bubble of time-shared cores (model/NOTES.md, session 80): over every interval of
// the runs above `cores` (one node, one-thread ranks bound round-robin, each rank's CPU per
// segment recorded), measured step / step replayed from that CPU (replay_time_shared at
// default_replay_slice_s) - 1 = intercept + per_phi x sharing_bubble_phi(the CPU); {"per_phi",
// "per_phi_se", "intercept", "intercept_se", "r2", "rse", "intervals",
// "intervals_phi_at_least_half", "intervals_phi_below_half", "slice_s", "runs", "method",
// "uses"}, or null with fewer than 3 intervals of phi >= 0.5 or of phi < 0.5.
nlohmann::json sharing_bubble(const std::vector<SphRun> &runs, int cores);

// The wall time of a run that no phase timer holds, per step: (wall_s - the slowest rank's
// timers summed per interval) / steps (the run's own bookkeeping between the timed phases).
double untimed_s_per_step(const SphRun &run);
// calibrate's "untimed_per_step": {"method", "layouts": [{"ranks", "threads", "runs",
// "median_s", "min_s", "max_s"}]}, one layout per ranks x threads the runs hold.
nlohmann::json untimed_per_step(const std::vector<SphRun> &runs);
// The seconds per step predict adds for `ranks` x `threads` from that section: the layout's
// median, else the nearest rank count's (the larger on a tie) at the same thread count, else
// at any; 0 without the section (a model from before session 94).
double untimed_s_per_step_for(const nlohmann::json &model, int ranks, int threads);
nlohmann::json speed_normalise(std::vector<SphRun> &runs, SpeedGauge mode,
                               GaugeReference reference = GaugeReference::pooled,
                               GaugeElasticity elasticity = GaugeElasticity::one, int cores = 0);
// The elasticity of the runs' compute to the speed gauge: least squares (GSL, fit_linear) of
// ln(compute per step per interaction) of every busy rank-interval on ln(the interval's gauge,
// pooled as `interval_gauges` holds it), with an intercept, a slope and a curvature in the
// run's time per run and rank (the flow's own trend through a run, and each rank's level, are
// theirs, not the gauge's); only runs within `cores` (0: all) and ranks with 4 or more such
// intervals. Returns {"value", "se", "points", "groups", "method"}, or null with too few
// points. `interval_gauges[i]` has one entry per interval of runs[i].
nlohmann::json gauge_elasticity(const std::vector<SphRun> &runs,
                                const std::vector<std::vector<double>> &interval_gauges, int cores);
// The same elasticity between the repeats of one configuration (the calibration's rounds):
// least squares (GSL) of ln(compute per interaction) of each run within `cores` (0: all) on
// ln(its whole gauge, SphRun::gauge_per_sample_s), a level per configuration run twice or
// more. Within a run the regressor is a 30 us sample pooled over three intervals, whose noise
// flattens the slope (errors in the variable): on this VM's Zen 4 host the estimate within
// runs read 0.38-0.78 in sixteen jobs where between repeats, pooled, it reads 0.92 (Cell+List
// and Cell+Table, standard error 0.03) and 1.01 (Cell+Sorted); model/NOTES.md, session 74.
// Returns {"value", "se", "runs", "configurations", "method"}, or null without repeats.
nlohmann::json gauge_elasticity_between_repeats(const std::vector<SphRun> &runs, int cores);
// Above this standard error the fitted elasticity is not used (the factor is applied whole).
constexpr double max_elasticity_se = 0.1;
// The exponent a model applies to the gauge's factor (model.json speed_gauge), 1 where it
// has none.
double gauge_elasticity_for(const nlohmann::json &speed_gauge);
// The gauge reference a prediction of `grid` at `threads` threads is at (model.json's
// speed_gauge): its group's where calibrate kept one per grid, else the pooled one; null when
// the gauge was not applied.
nlohmann::json gauge_reference_for(const nlohmann::json &speed_gauge, const std::string &grid,
                                   int threads);
nlohmann::json calibrate(const nlohmann::json &header, const nlohmann::json &machine,
                         const std::vector<SphRun> &runs, const CalibrateOptions &opt);
// The Froude-time profile of one compute entry (a fit of one grid and thread count, with its
// run_level) over those runs: per setup {"froude_time_s": [...], "factor": [...], "runs": n},
// measured / fitted compute of the busy ranks, rounds at the same times pooled. `factor` is a
// quadratic in Froude time fitted robustly (bisquare) to the intervals' ratios when `smooth`
// and there are 8 or more, else the ratio of sums over +-2 intervals (`factor_windowed`).
// With `shape_only`, each run's intervals are fitted at the run's own level (run_level/runs),
// so the profile is the cost's shape over Froude time and the setup's level stays the rule's.
nlohmann::json compute_time_profile(const nlohmann::json &entry,
                                    const std::vector<const SphRun *> &runs, bool smooth = true,
                                    bool shape_only = false);

// Seconds per step one fluid particle and one wall particle add to a rank: the calibrated
// compute fit of this grid and thread count, with the trace's interactions (and, for the
// stored-list grids, memory-order descents) per fluid particle at their median over the trace.
// The weights of sph's cost-aware balanced cuts (sph --decomposition balanced --model).
struct ColumnWeights {
    double fluid = 1, walls = 1;
    std::string source = "particle count";
};
ColumnWeights balance_weights(const nlohmann::json &model, const std::string &setup,
                              const std::string &grid, int threads);

// A prediction's band: this many standard deviations of ln(time) of the calibration runs about
// their setup's level either side (predict: wall_band; validate: within it or not).
inline constexpr double wall_band_sds = 2;

struct PredictRequest {
    std::string setup = "dambreak", grid = "table";
    double scale = 1, delta = 0.01, dt = 1e-4;
    std::vector<int> ranks{1, 2, 4};
    int threads = 1;
    std::optional<std::int64_t> steps;
    std::optional<double> end_time;
    int interval = 100;
    int cores = 0; // cores of the node (time-sharing above it); 0: from the model's machine
    // Nodes the ranks span, in blocks as srun -N places them (the first P mod N nodes get one
    // rank more); a shift between two nodes costs the machine's other_node Hockney class.
    int nodes = 1;
    // Equal slabs (the thesis'), balanced ones re-cut every `rebalance_every` steps (0: every
    // interval) by `weights`, or both (one configuration each per rank count).
    std::vector<std::string> decompositions{"equal"};
    int rebalance_every = 0;
    ColumnWeights weights;
    // sph --overlap (Cell+Sorted): the ghost and density exchanges run behind the interior
    // columns; each rank pays its received payloads' one-way Hockney time (model/NOTES.md).
    bool overlap = false;
    // The time-sharing overhead the calibration measured, added per step on a shared core
    // (per-step) or as a factor on its summed compute (ratio, the model before session 34).
    std::string time_sharing_overhead = "replay"; // since session 40 (model/NOTES.md)
    // replay: a shared node's step, comm and wait from the time-shared step replayed
    // (replay_time_shared, session 39) with this scheduler slice, not from an overhead.
    double replay_slice_s = default_replay_slice_s;
    // on: a replayed step times 1 + k phi, the pipeline bubble of cores that each time-share
    // two busy ranks (calibrate's time_sharing_bubble, fitted on its time-shared runs; phi:
    // sharing_bubble_phi of the predicted compute); off: the replay alone (the model of
    // sessions 40-79). model/NOTES.md, session 80.
    std::string time_sharing_bubble = "on";
    // on: every step also pays the wall time no phase timer holds, the run's own bookkeeping
    // (calibrate's untimed_per_step, per ranks x threads); off: the phases alone (the model of
    // sessions 1-93). model/NOTES.md, session 94.
    std::string untimed = "on";
    // columns: each list or table rank's compute per interaction follows the memory order of
    // its own columns (ColumnDisorder, session 56); none: every rank the whole run's profile.
    std::string rank_disorder = "columns";
    // simulated: each equal slab's Cell+Table memory order carried to the whole water's at the
    // target's simulated time (ColumnDisorder::at_whole_order, session 59); froude: at its
    // Froude time with the columns (sessions 56-58).
    std::string memory_order_time = "simulated";
    // With simulated: the share of that carry the cost follows, 0 (the cost at the order of
    // Froude time) to 1 (all of it, sessions 59-72); the order itself is carried whole. Over
    // seventeen replayed jobs the cost's course through the runs put the share near 0.3 on the
    // Zen 4 host and 0.6-1 on the earlier ones, and no calibration run measures it: half, the
    // share least wrong on either (model/NOTES.md, session 73; tuned).
    double memory_order_carry = 0.5;
    // The host speed the compute is predicted at: mean (the host's mean speed over the
    // calibration runs of the predicted grid, thread count and setup, calibrate's
    // speed_gauge.mean_factor.per_setup: what one run's sum of steps pays, its spells in their
    // share; session 76), mean-pooled (the same over every calibration run, session 75) or
    // median (the median calibration run's speed, which the median of repeated short runs
    // lands on; the model of sessions 50-74). model/NOTES.md, sessions 75-76.
    std::string host_speed = "mean";
    // on: each interval's compute at the host's drift within a run at that time since the
    // run's start, over the drift its setup's calibration runs hold (calibrate's
    // speed_gauge.run_drift); off, the default: the host speed alone. Replayed on 34 Zen 4
    // jobs it takes the mean signed error +3.1 -> +1.9 % and leaves the mean |error| as it is
    // (7.5 %); on seven earlier-host jobs, low already, -2.5 -> -2.7 %: a candidate, validated
    // beside in the main job (run-drift/; model/NOTES.md, session 79).
    std::string run_drift = "off";
};
nlohmann::json predict(const nlohmann::json &header, const nlohmann::json &model,
                       const PredictRequest &req);

// What a model exact in expectation would score on runs as noisy as the calibration runs: each
// configuration's measured time drawn as prediction x exp(sd z), z standard normal, with the
// log_sd of its band, and the median and the max of |error| over the configurations taken per
// draw. Quantiles over `draws` (a fixed seed: the same figures every time). It tells a miss of
// the model from one the host's run-to-run noise alone would make (model/NOTES.md, session 46).
struct Quantiles {
    double p05 = 0, median = 0, p95 = 0;
};
struct NoiseFloor {
    Quantiles median_abs_error, max_abs_error;
    std::size_t configurations = 0, draws = 0;
};
NoiseFloor wall_noise_floor(std::span<const double> log_sd, std::size_t draws = 20000);

struct ValidateOptions {
    std::optional<double> max_error; // fraction
};
// Returns the report; `exceeded` tells whether any total wall-time error passed max_error.
nlohmann::json validate(const nlohmann::json &header,
                        const std::vector<nlohmann::json> &predictions,
                        const std::vector<SphRun> &measured, const ValidateOptions &opt,
                        bool &exceeded);

// Text tables for stdout.
std::string calibration_table(const nlohmann::json &model);
std::string prediction_table(const nlohmann::json &prediction);
std::string validation_table(const nlohmann::json &validation);

} // namespace sphperf::model
