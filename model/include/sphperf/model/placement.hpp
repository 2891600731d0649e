#pragma once
// Where the launcher puts the ranks, and what a step costs when they take turns on the cores.
// Above the cores scripts/mpirun.sh binds one-thread ranks round-robin (rank r on core r mod C).
// Unbound, the scheduler paired the two busy ranks of the 4-rank dam break on one core in some
// runs and not in others: 3.4-6.1 s over 12 runs, 3.4-4.1 s over 11 runs bound (model/NOTES.md,
// "Time-sharing"). A core serves its ranks' compute one after the other (their phases are
// shorter than a scheduler slice), so a step lasts at least the busiest core's summed compute.
#include "sphperf/model/fit.hpp"

#include <array>
#include <optional>
#include <span>
#include <vector>

namespace sphperf::model {

// The first processing unit of each rank as scripts/mpirun.sh launches RANKS x THREADS on CORES
// cores: r x threads within the cores; r mod cores above them with one thread per rank; -1
// (unbound, placed by the scheduler) above them with more threads per rank.
std::vector<int> launcher_placement(int ranks, int threads, int cores);

struct SharedStep {
    double step_s = 0;        // compute per step of the busiest core, overhead included
    bool shared_core = false; // some core serves two or more busy ranks (the overhead applies)
};
// A time-shared step from each rank's compute per step and field particles (a rank without any
// is idle: it polls, yielding its core, and is not counted as busy). Bound ranks
// (every pu >= 0): per processing unit the summed compute, times `overhead` where that unit
// serves two or more busy ranks; the step lasts the busiest unit's. Unbound (any pu < 0): the
// summed compute x threads spread evenly over the cores, times `overhead`, and at least the
// slowest rank's. Throws std::invalid_argument on spans of different lengths.
SharedStep time_shared_step(std::span<const double> compute_s, std::span<const double> field,
                            std::span<const int> pus, int threads, int cores,
                            double overhead = 1.0);

// The time-sharing overhead per step of a shared core as a + b x its summed compute per step
// (terms "const" and "shared_compute"), fitted over the time-shared calibration runs of one
// load when there are at least 3 and their compute per step spans `min_span` or more (the runs
// of one step length cannot tell a from b); otherwise none. The model adds the median overhead
// per step unless asked for the line (predict --time-sharing-overhead line, session 37).
// Throws std::invalid_argument on spans of different lengths.
std::optional<LinearFit> fit_sharing_overhead(std::span<const double> compute_per_step_s,
                                              std::span<const double> overhead_per_step_s,
                                              double min_span = 2.0);

// The time-shared step replayed (session 39, model/NOTES.md; predict --time-sharing-overhead
// replay): one-thread ranks, rank r bound to core core_of[r], each step three segments of CPU
// work (cpu_s[r]: before the migration, the ghost and the density exchange), each followed by
// its exchange as the app makes it (a zero-byte handshake east then west: wait; counts and
// payloads east then west: comm). A computing rank keeps its core until its segment ends or
// `slice_s` has passed since it took the core; a rank in MPI yields its core while the message
// it waits for has not arrived; sends complete at once. Replays `steps` steps (the first two
// not counted) in ticks of `tick_s` and returns each rank's wait and comm per step (comm also
// per exchange) and the step. The transfers themselves cost nothing here: what it gives is the
// time a rank spends parked in its exchanges.
// Throws std::invalid_argument on no rank, a core index < 0 or of another length, slice or
// tick <= 0, or steps < 3.
struct ReplayedStep {
    std::vector<double> wait_s, comm_s;              // per rank, per step
    std::vector<std::array<double, 3>> shift_comm_s; // comm_s split by exchange
    double step_s = 0;
};
ReplayedStep replay_time_shared(const std::vector<std::array<double, 3>> &cpu_s,
                                const std::vector<int> &core_of, double slice_s, int steps = 20,
                                double tick_s = 5e-6);
// The same with the ranks bound round-robin to `cores` cores (scripts/mpirun.sh above the
// cores); throws std::invalid_argument on cores < 1.
ReplayedStep replay_time_shared(const std::vector<std::array<double, 3>> &cpu_s, int cores,
                                double slice_s, int steps = 20, double tick_s = 5e-6);

// The replay's slice by default (predict --replay-slice-ms): the kernel's EEVDF base slice on 2
// CPUs, 1.5 ms (tuned, session 40; model/NOTES.md).
inline constexpr double default_replay_slice_s = 1.5e-3;

// How fully every shared core carries two busy ranks (session 80): per core, the compute of its
// second busiest rank over its busiest's (0 where a core holds fewer than two ranks or none
// computes), the least of the cores that hold a rank. 1: every core time-shares two equal
// ranks (the balanced dam break on 4 ranks, 0.67; the half-scale still tank on 4 ranks, 0.95);
// 0: some core serves one rank alone, or one busy rank beside idle ones (every 3-rank run, the
// equal-slab dam breaks on 4 ranks, 0.00-0.01). Rank r is on core core_of[r]. Throws
// std::invalid_argument on spans of different lengths or a core index < 0.
double sharing_bubble_phi(std::span<const double> compute_s, std::span<const int> core_of);

} // namespace sphperf::model
