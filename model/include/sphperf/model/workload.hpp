#pragma once
// The workload side of the model: column histograms of field particles recorded over time (a
// trace), carried to another scale or spacing by similarity, and re-cut into exactly the app's
// slab decomposition to give every rank its field, wall, exported and ghost particles.
#include "sphperf/model/sph_run.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace sphperf::model {

struct Trace {
    std::string setup, source; // source: the calibration report it came from
    double scale = 1, delta = 0.01, cell_size = 0, tank_length = 0;
    std::vector<double> times_s;              // t = 0 first
    std::vector<std::vector<double>> columns; // fluid particles per column at each time
    // Pairs and interactions per field particle at each time, summed over ranks. The flow sets
    // them (the collapsing column compresses and spreads): measured at scales 0.5, 1 and 2 they
    // agree at equal Froude time, not at equal simulated time.
    std::vector<double> pairs_per_field, interactions_per_field;

    double end_time() const { return times_s.empty() ? 0 : times_s.back(); }
    nlohmann::json to_json() const;
    static Trace from_json(const nlohmann::json &j, const std::string &where);
};

Trace trace_of(const SphRun &run);

// What the model needs of a configuration it predicts, from the app's own geometry code.
struct Target {
    std::string setup, grid, boundary = "fixed";
    double scale = 1, delta = 0.01, dt = 1e-4, cell_size = 0, tank_length = 0;
    int columns = 0, ranks = 1, threads = 1;
    double fluid_particles = 0;
    std::vector<double> wall_columns, initial_columns;
};
// Throws UsageError for an unknown setup or more ranks than columns.
Target make_target(const std::string &setup, const std::string &grid, double scale, double delta,
                   double dt, int ranks, int threads);

// Froude similarity: lengths scale with s, times with sqrt(s), so the target at time t looks
// like the source at t sqrt(s_source / s_target). Spacing changes only the particle count.
double source_time(double target_time, double source_scale, double target_scale);

// The source histogram carried onto the target's columns: target column [a, b) takes the
// source particles in [a, b) / (tank_t / tank_s) (fractions of columns by overlap), scaled so
// the total equals the target's own field-particle count.
std::vector<double> rescale_columns(const std::vector<double> &source, double source_cell,
                                    double source_tank, double target_cell, double target_tank,
                                    int target_columns, double target_total);

// The trace's histogram at a source time, linear in time between records; throws UsageError
// naming the simulated time needed when the trace ends before it.
std::vector<double> histogram_at(const Trace &trace, double source_time);

// Pairs and interactions per field particle at a source time, linear between records.
struct WorkDensity {
    double pairs = 0, interactions = 0;
};
WorkDensity density_at(const Trace &trace, double source_time);

struct SlabLoad {
    int begin = 0, end = 0; // columns owned
    double field = 0;       // fluid particles owned
    double walls = 0;       // wall particles owned (fixed boundary)
    double exported = 0;    // particles of the edge columns facing a neighbour, both sides
    double export_west = 0, export_east = 0;
    double ghost = 0; // particles received from the neighbours' facing edge columns
};
// Exactly the app's decomposition (sph::Slab::first_column) and its edge-column export rule.
std::vector<SlabLoad> recut(const std::vector<double> &fluid_columns,
                            const std::vector<double> &wall_columns, int ranks);
// The same for any valid cuts (sph/balance.hpp: the balanced decomposition).
std::vector<SlabLoad> recut(const std::vector<double> &fluid_columns,
                            const std::vector<double> &wall_columns, const std::vector<int> &cuts);

// Thesis 3.7.3: until the water reaches a slab its rank idles. The first step at which each
// slab of `cuts`, and then every slab, holds at least one field particle, on the trace carried
// to the target; empty: not within `steps`. Scanned every step up to 20,000 looks, then coarser.
struct IdleOnset {
    std::optional<std::int64_t> all;
    std::vector<std::optional<std::int64_t>> per_rank;
};
IdleOnset idle_onset(const Trace &trace, const Target &target, const std::vector<int> &cuts,
                     double dt, std::int64_t steps);

// How far the particles' memory order has decayed from the initial lattice, as the stored-list
// grids see it: neighbours found out of id order per interaction (the id sort's work, and the
// scattered reads of the candidate scan). Measured at scales 0.5, 1 and 2 it is one function of
// simulated time, not of Froude time: the order decays with the particles' jitter on the
// acoustic time scale (spacing / sound speed, the same at every scale here), not with the flow.
struct Disorder {
    std::string source;
    double delta = 0.01; // spacing of the runs it was measured in
    std::vector<double> times_s, per_interaction;
    // Linear in time between records; throws UsageError naming the time needed past the end.
    double at(double time_s, double target_delta) const;
    nlohmann::json to_json() const;
    static Disorder from_json(const nlohmann::json &j, const std::string &where);
};
// Mean over the given runs (same setup, list or table grid, identical record times) of the
// descents per interaction summed over ranks, at t = 0 taken equal to the first record.
Disorder disorder_of(const std::vector<SphRun> &runs);

// Where the memory order has decayed: per cell column, the interactions and descents of the
// particles filed there, and how a rank's compute per interaction follows its descents per
// interaction. The disorder sits where the water moves: at 0.13 s of a 4-rank dam break at
// scale 1 (Cell+Table) the back rank read 0.21 descents per interaction and 20.7 ns of search
// and id sort per interaction, the front rank 0.40 and 28.3 ns, and one profile for every rank
// put the back rank, which sets the wall time, 6 % high (model/NOTES.md, session 55). The
// columns follow the flow (Froude time); the cost line is fitted on the runs' busy
// rank-intervals over the later half of their reach (earlier the collapse raises the cost
// before the ids disorder), one level per run.
struct ColumnDisorder {
    std::string source;
    // The runs whose per-column descents stand for the memory order (Cell+Table's, for
    // Cell+List: below); empty: the runs' own.
    std::string order_source;
    double scale = 1, cell_size = 0, tank_length = 0;
    std::vector<double> times_s;
    std::vector<std::vector<double>> interactions, descents; // per column, at each time
    // Compute seconds per interaction per step = intercept + slope x descents per interaction
    // (at the speed gauge's reference speed where the runs carry it).
    double intercept_s = 0, slope_s = 0, intercept_se_s = 0, slope_se_s = 0, r2 = 0;
    std::size_t points = 0;
    // How the times were put at one speed where it was not the rule's first gauge (calibrate
    // --order-line-gauge interval-or-kernel); empty otherwise.
    std::string gauge_note;

    // Descents per interaction of every slab of `cuts` (none for a slab without interactions)
    // and of all the columns, the columns carried to the target (scale, cell size, tank
    // length, columns) at its simulated time `target_time_s` by Froude time. Throws UsageError
    // naming the time needed when the record ends before it.
    struct SlabOrder {
        std::vector<std::optional<double>> slabs;
        double all = 0;
    };
    SlabOrder slab_order(double target_time_s, double target_scale, double target_cell,
                         double target_tank, int target_columns,
                         const std::vector<int> &cuts) const;
    // Every slab's compute per interaction over the whole water's: (a + b D_slab) /
    // (a + b D_all); 1 for a slab without interactions.
    std::vector<double> factors(const SlabOrder &order) const;
    // `order` with every slab's descents per interaction scaled by whole / order.all: the
    // columns follow the flow (Froude time), but the whole water's memory order follows
    // simulated time (the particles' jitter on the acoustic time scale: at equal Froude time
    // a scale-1 dam break has run 1.41 times as long as the half-scale record, and reads
    // 0.31 descents per interaction at 0.15 s where the record carried 0.23; session 59).
    // order.all stays: it is the order the Froude-time profile's cost was measured at, so
    // factors() then carries each rank from it to its own order at the target's time.
    static SlabOrder at_whole_order(SlabOrder order, double whole);
    std::vector<double> rank_factors(double target_time_s, double target_scale, double target_cell,
                                     double target_tank, int target_columns,
                                     const std::vector<int> &cuts) const;
    double end_time() const { return times_s.empty() ? 0 : times_s.back(); }
    // Why the line cannot carry one rank's order to another, empty when it can: it needs a
    // positive cost at no disorder and a slope above two standard errors. Cell+List's descents
    // stay at 0.86 per interaction through a dam break (each cell's list is in reverse filing
    // order, whatever the memory order), and a still tank's barely move: their lines are noise.
    std::string unusable() const;
    nlohmann::json to_json() const;
    static ColumnDisorder from_json(const nlohmann::json &j, const std::string &where);
};
// From runs of one setup and grid with identical record times (rounds); nullopt when they carry
// no per-column counts or too few points for the line. The runs' times as given (normalise
// them to one speed first). With `order_runs` (same setup, scale, columns and record times),
// the columns' interactions and descents are theirs and each rank-interval of `runs` reads its
// descents per interaction over its equal slab's columns there: Cell+List's own descents stay
// at 0.86 per interaction whatever the memory order (each cell's list is in reverse filing
// order), while its particles move, and migrate, as Cell+Table's do (the same physics): its
// cost per interaction follows Cell+Table's descents in the same columns (session 57: R^2
// 0.92-0.96 over the later half of the half-scale dam breaks, against 0.93-0.97 for
// Cell+Table's own).
std::optional<ColumnDisorder> column_disorder_of(const std::vector<SphRun> &runs,
                                                 const std::vector<SphRun> &order_runs = {});
// The runs with each interval's times divided by its speed gauge (the median over
// +-half_window intervals) over the run's whole: the run's level stays, a spell of a faster or
// slower host within it goes. For the cost line above, fitted within runs. Runs without gauge
// samples stay as they are.
std::vector<SphRun> within_run_speed(std::vector<SphRun> runs, int half_window);
// The runs with each rank-interval's times divided by its own SPH kernel's time per interaction
// (the `comp_s` timer over steps x interactions) over the run's median of it: the kernel runs
// on the same core over the same particles and barely follows the memory order, so it gauges
// the host's speed in that rank-interval where the gauge samples are too few. It also takes
// out the kernel's own small rise with the order (about a quarter of the line's slope on a
// quiet host, model/NOTES.md session 93). Rank-intervals without kernel time stay as they are.
std::vector<SphRun> within_run_kernel_speed(std::vector<SphRun> runs);

} // namespace sphperf::model
