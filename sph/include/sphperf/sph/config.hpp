#pragma once
// Everything a run is made of, parsed once in main: setup, grid, boundary, physics parameters.
#include "sphperf/sph/kernel.hpp"

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace sphperf::sph {

enum class Setup { dambreak, still, column };
enum class GridKind { list, table, sorted };
enum class BoundaryKind { mirror, fixed };
enum class Decomposition { equal, balanced };
// How ghosts and their densities travel: MPI messages, or an MPI-3 shared-memory window.
enum class HaloTransport { messages, window };

Setup parse_setup(std::string_view s);
GridKind parse_grid(std::string_view s);
BoundaryKind parse_boundary(std::string_view s);
Decomposition parse_decomposition(std::string_view s);
HaloTransport parse_halo_transport(std::string_view s);
std::string_view to_string(Setup s);
std::string_view to_string(GridKind g);
std::string_view to_string(BoundaryKind b);
std::string_view to_string(Decomposition d);
std::string_view to_string(HaloTransport t);

// Weakly compressible SPH parameters. Values and reasons are in sph/README.md.
struct Physics {
    double rho0 = 1000.0;   // reference density, kg/m^3
    double c0 = 50.0;       // numerical speed of sound, m/s (>= 10 x the flow speed)
    double gamma = 7.0;     // Tait exponent
    double gravity = 9.81;  // m/s^2
    double alpha = 0.2;     // Monaghan artificial viscosity (see sph/README.md)
    double delta = 0.01;    // particle spacing, m
    double h = 0.0;         // smoothing length 0.94 delta sqrt(2)
    int shepard_every = 30; // density re-initialisation period, steps
    static constexpr double h_factor = 0.94;
    static constexpr double cfl = 0.4; // Monaghan's acoustic limit: dt <= 0.4 h / c0

    double tait_b() const { return c0 * c0 * rho0 / gamma; }
    double pressure(double rho) const {
        const double r = rho / rho0;
        // gamma = 7 by three multiplications: the pass vectorises, and std::pow took 3 % of a
        // Cell+Sorted step (sph/NOTES.md). Another exponent takes std::pow.
        if (gamma == 7.0) {
            const double r2 = r * r, r4 = r2 * r2;
            return tait_b() * (r4 * r2 * r - 1.0);
        }
        return tait_b() * (std::pow(r, gamma) - 1.0);
    }
    double density(double pressure) const {
        return rho0 * std::pow(1.0 + pressure / tait_b(), 1.0 / gamma);
    }
    double particle_mass() const { return rho0 * delta * delta; }
    double max_dt() const { return cfl * h / c0; }
    QuinticKernel kernel() const { return QuinticKernel(h); }
    double cell_size() const { return QuinticKernel::support_factor * h; }
};

// The tank and the initial block of fluid, in metres, after scaling.
struct Geometry {
    double tank_length = 0; // B
    double dam_width = 0;   // L
    double dam_height = 0;  // T
    double dam_x0 = 0, dam_y0 = 0;
    double ceiling = 0; // 1.5 T: particles above it are stored in the top cell row
    int fluid_columns = 0, fluid_rows = 0; // particles along x and y
    int cell_columns = 0, cell_rows = 0;   // cells over the tank (no ghost columns/rows)
    double cell_size = 0;

    std::int64_t fluid_particles() const {
        return static_cast<std::int64_t>(fluid_columns) * fluid_rows;
    }
};

// A deliberate failure on one rank at one step, for the tests of the abort path: environment
// SPHPERF_INJECT_FAULT="KIND:RANK:STEP", KIND `throw` (an exception), `nan` (a NaN velocity) or
// `leak` (a fluid particle below the floor), the last two caught by the state check. Never set
// in production runs.
struct FaultInjection {
    enum class Kind { exception, nan, leak };
    Kind kind = Kind::exception;
    int rank = 0;
    std::int64_t step = 0;
};
// Parses "KIND:RANK:STEP"; throws UsageError naming the value.
FaultInjection parse_fault(std::string_view s);

// What a column costs per step in the balanced decomposition: weight times its fluid particles
// plus weight times its wall particles. By default both count as particles do in the neighbour
// search (one each); with --model the calibrated performance model's compute coefficients
// (model/NOTES.md) give seconds instead.
struct BalanceWeights {
    double fluid = 1.0, walls = 1.0;
    std::string source = "particle count";
};

struct Config {
    Setup setup = Setup::dambreak;
    GridKind grid = GridKind::table;
    BoundaryKind boundary = BoundaryKind::fixed;
    double scale = 1.0;
    double column_width = 0.3; // a, column setup only
    double dt = 1e-4;
    std::optional<std::int64_t> steps;
    std::optional<double> end_time;
    int threads = 0; // 0: OMP_NUM_THREADS / runtime default
    int interval = 1000;
    std::optional<std::filesystem::path> report;
    std::optional<std::filesystem::path> machine; // machine.json: predict each message inline
    // An exchange benchmark report that costs the shifts in place of the profile's (one measured
    // right before the run, on a machine whose exchange costs drift).
    std::optional<std::filesystem::path> exchange;
    // Above the cores (--machine): the scheduler slice of the replay that predicts the
    // time-shared step's transfers (sph/README.md; 1.5 ms, tuned, model/NOTES.md).
    double replay_slice_ms = 1.5;
    std::optional<std::filesystem::path> vtk_dir;
    int vtk_every = 0;
    bool quiet = false;
    std::optional<std::filesystem::path> checkpoint_dir; // write checkpoints here
    int checkpoint_every = 0;                            // steps; 0: the report interval
    std::optional<std::filesystem::path> restart_dir;    // continue from its latest checkpoint
    std::optional<FaultInjection> fault;
    Decomposition decomposition = Decomposition::equal;
    int rebalance_every = 0;                         // steps; 0: the report interval
    std::optional<std::filesystem::path> cost_model; // model.json for cost-aware cuts
    BalanceWeights balance;
    bool overlap = false; // non-blocking ghost exchanges behind the interior columns (sorted)
    HaloTransport halo_transport = HaloTransport::messages;
    int reorder_every = 0;      // steps between permuting the particles into cell order; 0: never
    int speed_gauge_every = 10; // steps between samples of the speed gauge (gauge.hpp); 0: none
    // With it, the core latency gauge's (gauge.hpp) where the rank has two or more threads and
    // they do not take turns on cores (set by main from the placement, not an option).
    bool core_latency_gauge = true;
    Physics physics;

    std::int64_t total_steps() const;
};

// Thesis geometry (3.1, 3.6.1): dam L = 1.2, T = 0.6 in a tank B = 3.22, times scale.
Geometry make_geometry(const Config &cfg);

// Checks values that parsing alone cannot (ranges, CFL); throws UsageError.
void validate(const Config &cfg, const Geometry &geo, int ranks);

} // namespace sphperf::sph
