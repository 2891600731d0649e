// sphmodel: calibrate the SPH runtime model, predict runs per rank count, validate predictions.
#include "sphperf/cli.hpp"
#include "sphperf/model/profile.hpp"
#include "sphperf/model/runtime.hpp"
#include "sphperf/report.hpp"
#include "sphperf/topology.hpp"

#include <cmath>
#include <cstdio>
#include <iostream>

namespace {

using namespace sphperf;
using namespace sphperf::model;

struct Options {
    std::filesystem::path machine, model, out;
    std::vector<std::filesystem::path> runs, predictions, measured;
    bool allow_other_host = false;
    std::string term_selection = "levelled-best";
    std::string time_profile = "froude";
    std::string fit_weights = "relative";
    std::string run_level = "pooled";
    std::string speed_gauge = "run";
    std::string gauge_reference = "pooled";
    std::string gauge_elasticity = "one";
    std::string order_line_gauge = "interval-or-kernel";
    bool walls_term = false;
    std::string jitter_form = "auto";
    std::string item_cost_bound = "particle";
    std::string cv_hold_out = "run";
    PredictRequest predict;
    std::string balance_weights = "count";
    std::int64_t steps = 0;
    double end_time = 0, max_error = 0;
};

int run(int argc, char **argv) {
    Options o;
    cli::App app{"The SPH runtime model: calibrate it from SPH reports and a machine profile, "
                 "predict the wall time per rank count with its breakdown, and validate "
                 "predictions against measured reports."};
    app.require_subcommand(1);
    app.column_width(34);

    auto *cal = app.add_subcommand("calibrate", "Fit the model to SPH reports");
    cal->add_option("--machine", o.machine, "machine.json (machine-profile)")
        ->required()
        ->check(cli::ExistingFile);
    cal->add_option("--runs", o.runs, "SPH reports (sph --report) to calibrate with")
        ->required()
        ->check(cli::ExistingFile);
    cal->add_option("--out", o.out, "model to write (JSON)")->required();
    cal->add_flag("--allow-other-host", o.allow_other_host,
                  "Accept reports measured on another host than the machine profile's");
    cal->add_option("--term-selection", o.term_selection,
                    "Compute-cost terms: levelled-one-se (a cost level per setup, the smallest "
                    "set within one standard error of the best cross-validation score), "
                    "levelled-best (the same levels, the set with the best score) or "
                    "pooled-one-percent (one pooled fit, a term kept for 1 % better score)")
        ->capture_default_str()
        ->check(cli::IsMember({"levelled-one-se", "levelled-best", "pooled-one-percent"}));
    cal->add_option("--time-profile", o.time_profile,
                    "How the cost of an interaction evolves with the flow: froude (a profile of "
                    "measured / fitted compute over Froude time from the calibration runs, a "
                    "quadratic fitted robustly), froude-windowed (the same profile as a moving "
                    "ratio over +-2 intervals, sessions 16-41) or none (the fit alone, with the "
                    "memory-order term descents at simulated time)")
        ->capture_default_str()
        ->check(cli::IsMember({"froude", "froude-windowed", "none"}));
    cal->add_option("--fit-weights", o.fit_weights,
                    "How the compute-cost fit and its cross-validation weigh the rank-intervals: "
                    "absolute (seconds per step) or relative (each divided by its run's median "
                    "step, so small-scale runs count as much as large ones)")
        ->capture_default_str()
        ->check(cli::IsMember({"absolute", "relative"}));
    cal->add_option("--run-level", o.run_level,
                    "A setup's cost level from its calibration runs: pooled (the pooled level "
                    "of all runs, through the time profile: a mean, which is what a sum of "
                    "step times pays), fastest-repeat (the fastest run of each repeated "
                    "configuration, the median over configurations; the profile carries the "
                    "shape only: sessions 43-44) or median (the median run, the same profile)")
        ->capture_default_str()
        ->check(cli::IsMember({"fastest-repeat", "median", "pooled"}));
    cal->add_option("--speed-gauge", o.speed_gauge,
                    "run (each run's times divided by its whole speed gauge over the runs' "
                    "median, sph --speed-gauge-every; applied when every run carries it: "
                    "sessions 50 and 85 on), interval (each interval's by the gauge around it, "
                    "the median over +-1 interval: sessions 51-84, whose calibration runs came "
                    "out 1-2 % dearer than by their run's gauge, model/NOTES.md session 85), "
                    "interval-mean (the same with the window's mean, sessions 51-53) or off "
                    "(the runs as measured, sessions 1-49)")
        ->capture_default_str()
        ->check(cli::IsMember({"interval", "interval-mean", "run", "off"}));
    cal->add_option("--speed-gauge-reference", o.gauge_reference,
                    "pooled (every run at all the runs' median gauge, sessions 50-58) or grid "
                    "(each grid and thread count's runs at their own median: the gauge reads "
                    "differently with what runs around it, model/NOTES.md session 58)")
        ->capture_default_str()
        ->check(cli::IsMember({"grid", "pooled"}));
    cal->add_option("--speed-gauge-elasticity", o.gauge_elasticity,
                    "one (the times divided by the gauge's factor itself, sessions 50-74) or "
                    "fitted (by the factor raised to the elasticity of the runs' compute to the "
                    "gauge, fitted between the repeats of a configuration, else within runs, "
                    "and reported either way: about 1 between repeats on this VM, "
                    "model/NOTES.md session 74)")
        ->capture_default_str()
        ->check(cli::IsMember({"fitted", "one"}));
    cal->add_option("--order-line-gauge", o.order_line_gauge,
                    "The memory order's cost line over times put at one speed within each run "
                    "by the speed gauge around every interval (interval: a slow spell inside "
                    "the long run flattened it otherwise, model/NOTES.md session 91), at the "
                    "run's whole speed only, as the other fits (run: sessions 56-90), by each "
                    "rank-interval's own kernel time per interaction (kernel), or by the "
                    "interval gauge and, where that line is unusable, the kernel "
                    "(interval-or-kernel, session 93)")
        ->capture_default_str()
        ->check(cli::IsMember({"interval", "run", "kernel", "interval-or-kernel"}));
    cal->add_flag("--walls-term", o.walls_term,
                  "Also offer the compute-cost term walls (every wall particle of a rank), as "
                  "sessions 1-50 did (a rank's dry walls cost nothing measurable: model/NOTES.md, "
                  "session 51)");
    cal->add_option("--item-cost-bound", o.item_cost_bound,
                    "particle (a term set that prices one owned or ghost particle, cell move or "
                    "wall above a fluid particle's interactions is refused, since session 73) "
                    "or none (any positive cost, sessions 1-72)")
        ->capture_default_str()
        ->check(cli::IsMember({"particle", "none"}));
    cal->add_option("--cv-hold-out", o.cv_hold_out,
                    "What the term selection's cross-validation holds out at a time: run (one "
                    "calibration run) or configuration (every repeat of one configuration where "
                    "its setup ran two or more, so terms are scored on a scale they did not "
                    "see; replayed on 66 main jobs it did worse: model/NOTES.md, session 81)")
        ->capture_default_str()
        ->check(cli::IsMember({"run", "configuration"}));
    cal->add_option("--jitter-form", o.jitter_form,
                    "How a rank's step-to-step compute noise grows with its step: auto (the "
                    "form whose leave-one-run-out prediction of the calibration runs' waits is "
                    "closer, since session 61), sqrt (standard deviation k sqrt(compute), "
                    "sessions 15-60) or proportional (k compute, sessions 1-14)")
        ->capture_default_str()
        ->check(cli::IsMember({"auto", "sqrt", "proportional"}));

    auto &q = o.predict;
    auto *pre = app.add_subcommand("predict", "Predict the runtime per rank count");
    pre->add_option("--model", o.model, "model.json (sphmodel calibrate)")
        ->required()
        ->check(cli::ExistingFile);
    pre->add_option("--setup", q.setup, "Setup")
        ->capture_default_str()
        ->check(cli::IsMember({"dambreak", "still", "column"}));
    pre->add_option("--grid", q.grid, "Cell grid scheme")
        ->capture_default_str()
        ->check(cli::IsMember({"list", "table", "sorted"}));
    pre->add_option("--scale", q.scale, "Geometry scale")
        ->capture_default_str()
        ->check(FinitePositive);
    pre->add_option("--delta", q.delta, "Particle spacing, m")
        ->capture_default_str()
        ->check(FinitePositive);
    pre->add_option("--dt", q.dt, "Time step, s")->capture_default_str()->check(FinitePositive);
    pre->add_option("--ranks", q.ranks, "Rank counts, comma separated")
        ->delimiter(',')
        ->capture_default_str()
        ->check(cli::Range(1, 1 << 20));
    pre->add_option("--threads", q.threads, "OpenMP threads per rank")
        ->capture_default_str()
        ->check(cli::Range(1, 1024));
    auto *o_steps = pre->add_option("--steps", o.steps, "Time steps")
                        ->check(cli::Range(std::int64_t{1}, std::int64_t{1} << 40));
    auto *o_end =
        pre->add_option("--end-time", o.end_time, "Simulated time, s")->check(FinitePositive);
    o_steps->excludes(o_end);
    pre->add_option("--interval", q.interval, "Steps per predicted interval (as sph --interval)")
        ->capture_default_str()
        ->check(cli::Range(1, 1 << 30));
    pre->add_option("--decomposition", q.decompositions,
                    "Slabs, comma separated: equal (the thesis'), balanced (sph --decomposition "
                    "balanced, particle-count weights) or both")
        ->delimiter(',')
        ->capture_default_str()
        ->check(cli::IsMember({"equal", "balanced"}));
    pre->add_option("--balance-weights", o.balance_weights,
                    "Balanced slabs weighted as sph cuts them: count (its default) or model "
                    "(sph --model: this model's seconds per fluid and wall particle)")
        ->capture_default_str()
        ->check(cli::IsMember({"count", "model"}));
    pre->add_option("--rebalance-every", q.rebalance_every,
                    "Steps between re-cuts of balanced slabs (as sph; 0: every interval)")
        ->capture_default_str()
        ->check(cli::Range(0, 1 << 30));
    pre->add_option("--cores", q.cores, "Cores of the node (default: the model's machine)")
        ->check(cli::Range(1, 1 << 20));
    pre->add_option("--nodes", q.nodes,
                    "Nodes the ranks span, in blocks as srun -N places them (> 1 needs the "
                    "machine's other_node class: scripts/slurm/pingpong-nodes.sbatch)")
        ->capture_default_str()
        ->check(cli::Range(1, 1 << 20));
    pre->add_flag("--overlap", q.overlap,
                  "As sph --overlap (Cell+Sorted only): ghost and density exchanges behind the "
                  "interior columns");
    pre->add_option("--time-sharing-overhead", q.time_sharing_overhead,
                    "Above the cores: the step replayed (replay: who runs while whom waits, "
                    "one-thread ranks on one node; elsewhere per-step), or the calibration's "
                    "time-sharing overhead added per step on a shared core (per-step: the median; "
                    "the model of sessions 34-39), as a line in its summed compute where "
                    "calibration fitted one (line; else per-step), or as a factor on it (ratio, "
                    "the model before session 34)")
        ->capture_default_str()
        ->check(cli::IsMember({"per-step", "line", "ratio", "replay"}));
    pre->add_option_function<double>(
           "--replay-slice-ms", [&q](double ms) { q.replay_slice_s = ms * 1e-3; },
           "With --time-sharing-overhead replay: the scheduler slice of a computing rank, ms "
           "(default 1.5: the kernel's EEVDF base slice on 2 CPUs; tuned, model/NOTES.md)")
        ->check(FinitePositive);
    pre->add_option("--time-sharing-bubble", q.time_sharing_bubble,
                    "With the replay: on: a replayed step times 1 + k phi, the bubble of cores "
                    "that each time-share two busy ranks, k from the calibration's time-shared "
                    "runs (calibrate's time_sharing_bubble; phi: per core the second busiest "
                    "rank's compute over the busiest's, the least over the cores); off: the "
                    "replay alone (model/NOTES.md, session 80)")
        ->capture_default_str()
        ->check(cli::IsMember({"on", "off"}));
    pre->add_option("--untimed", q.untimed,
                    "on: every step also pays the wall time no phase timer holds (the run's "
                    "own bookkeeping, calibrate's untimed_per_step, the median of the "
                    "calibration runs of the same ranks x threads); off: the phases alone "
                    "(model/NOTES.md, session 94)")
        ->capture_default_str()
        ->check(cli::IsMember({"on", "off"}));
    pre->add_option("--rank-disorder", q.rank_disorder,
                    "List and table: each rank's compute per interaction from the memory order "
                    "of its own columns (columns: the calibration's per-column descents, where "
                    "the model has them), or every rank the whole run's (none: the model "
                    "before session 56)")
        ->capture_default_str()
        ->check(cli::IsMember({"columns", "none"}));
    pre->add_option("--memory-order-time", q.memory_order_time,
                    "Table: each equal slab's memory order carried to the whole water's at the "
                    "target's simulated time (simulated: the descents follow the particles' "
                    "jitter, model/NOTES.md session 59), or with its columns at the target's "
                    "Froude time (froude: sessions 56-58 and 90), or each column's own order at "
                    "the target's simulated time (columns: the main job's since session 91)")
        ->capture_default_str()
        ->check(cli::IsMember({"simulated", "froude", "columns"}));
    pre->add_option("--memory-order-carry", q.memory_order_carry,
                    "With --memory-order-time simulated: the share of the order's carry from "
                    "Froude time to simulated time that its cost follows, 0 (none: the cost as "
                    "froude) to 1 (all, sessions 59-72); the order itself is carried whole "
                    "(default 0.5: tuned, model/NOTES.md session 73)")
        ->capture_default_str()
        ->check(cli::Range(0.0, 1.0));
    pre->add_option("--host-speed", q.host_speed,
                    "The host speed the compute is predicted at: mean (the host's mean speed "
                    "over the calibration runs of the predicted grid, thread count and setup, "
                    "their fast spells in their share: what one run's sum of steps pays; "
                    "session 76), mean-pooled (the same over every calibration run, session 75) "
                    "or median (the median calibration run's speed, where the median of "
                    "repeated short runs lands; sessions 50-74). The main job predicts its long "
                    "single runs (the list and table dam breaks, 8-30 s) at the mean and the "
                    "others at the median (model/NOTES.md, sessions 75-76)")
        ->capture_default_str()
        ->check(cli::IsMember({"mean", "mean-pooled", "median"}));
    pre->add_option("--run-drift", q.run_drift,
                    "on: each interval's compute at the host's speed drift within a run at its "
                    "time since the run's start (the gauge 2-4 % faster after the first seconds "
                    "on the VM's Zen 4 host), over the drift its setup's calibration runs hold "
                    "(calibrate's speed_gauge.run_drift); off: the host speed alone (a candidate "
                    "not yet in use, validated beside in the main job's run-drift/: "
                    "model/NOTES.md, session 79)")
        ->capture_default_str()
        ->check(cli::IsMember({"on", "off"}));
    pre->add_option("--out", o.out, "prediction to write (JSON)")->required();

    auto *val = app.add_subcommand("validate", "Compare predictions with measured SPH reports");
    val->add_option("--prediction", o.predictions, "prediction files (sphmodel predict)")
        ->required()
        ->check(cli::ExistingFile);
    val->add_option("--measured", o.measured, "measured SPH reports")
        ->required()
        ->check(cli::ExistingFile);
    auto *o_max = val->add_option("--max-error", o.max_error,
                                  "Exit 1 when a wall-time |error| exceeds this fraction")
                      ->check(FiniteNonNegative);
    val->add_option("--out", o.out, "validation report to write (JSON)")->required();
    parse_cli(app, argc, argv);

    const JsonSink sink(o.out);
    const Topology topo;
    if (cal->parsed()) {
        const auto machine = load_report(o.machine, "machine");
        std::vector<SphRun> runs;
        for (const auto &r : o.runs)
            runs.push_back(load_sph_run(r));
        const auto model = calibrate(
            report_header("sphmodel-calibration", topo), machine, runs,
            {o.allow_other_host,
             o.term_selection == "pooled-one-percent" ? TermSelection::pooled_one_percent
             : o.term_selection == "levelled-one-se"  ? TermSelection::levelled_one_se
                                                      : TermSelection::levelled_best,
             o.time_profile == "none"              ? TimeProfile::none
             : o.time_profile == "froude-windowed" ? TimeProfile::froude_windowed
                                                   : TimeProfile::froude,
             o.fit_weights == "relative" ? FitWeights::relative : FitWeights::absolute,
             o.run_level == "fastest-repeat" ? RunLevelRule::fastest_repeat
             : o.run_level == "median"       ? RunLevelRule::median
                                             : RunLevelRule::pooled,
             o.speed_gauge == "interval"        ? SpeedGauge::interval
             : o.speed_gauge == "interval-mean" ? SpeedGauge::interval_mean
             : o.speed_gauge == "run"           ? SpeedGauge::run
                                                : SpeedGauge::off,
             o.gauge_reference == "pooled" ? GaugeReference::pooled : GaugeReference::grid,
             o.gauge_elasticity == "one" ? GaugeElasticity::one : GaugeElasticity::fitted,
             o.order_line_gauge == "run"                  ? OrderLineGauge::run
             : o.order_line_gauge == "kernel"             ? OrderLineGauge::kernel
             : o.order_line_gauge == "interval-or-kernel" ? OrderLineGauge::interval_or_kernel
                                                          : OrderLineGauge::interval,
             o.walls_term,
             o.jitter_form == "auto"   ? std::nullopt
             : o.jitter_form == "sqrt" ? std::optional<JitterForm>(JitterForm::sqrt)
                                       : std::optional<JitterForm>(JitterForm::proportional),
             o.item_cost_bound == "particle",
             o.cv_hold_out == "configuration" ? CvHoldOut::configuration : CvHoldOut::run});
        std::cout << calibration_table(model);
        sink.write(model);
    } else if (pre->parsed()) {
        if (!o_steps->count() && !o_end->count())
            throw UsageError("give the run length with --steps N or --end-time SECONDS");
        if (o_steps->count())
            q.steps = o.steps;
        else
            q.end_time = o.end_time;
        const auto model = load_report(o.model, "sphmodel-calibration");
        if (o.balance_weights == "model")
            q.weights = balance_weights(model, q.setup, q.grid, q.threads);
        const auto prediction = predict(report_header("sphmodel-prediction", topo), model, q);
        std::cout << prediction_table(prediction);
        sink.write(prediction);
    } else {
        std::vector<nlohmann::json> predictions;
        for (const auto &p : o.predictions)
            predictions.push_back(load_report(p, "sphmodel-prediction"));
        std::vector<SphRun> measured;
        for (const auto &m : o.measured)
            measured.push_back(load_sph_run(m));
        ValidateOptions opt;
        if (o_max->count())
            opt.max_error = o.max_error;
        bool exceeded = false;
        const auto v = validate(report_header("sphmodel-validation", topo), predictions, measured,
                                opt, exceeded);
        std::cout << validation_table(v);
        sink.write(v);
        if (exceeded) {
            std::cerr << "sphmodel: a wall-time error exceeds --max-error " << o.max_error << '\n';
            return exit_failure;
        }
    }
    std::cout << "written " << o.out.string() << '\n';
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    return sphperf::guarded_main("sphmodel", [&] { return run(argc, argv); });
}
