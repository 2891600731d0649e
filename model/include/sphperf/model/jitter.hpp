#pragma once
// Step-to-step jitter of the ranks' compute. The exchange is blocking, so every step lasts as long
// as its slowest rank: with equal work on every rank the step still costs the expected maximum
// of their noisy compute times, not their mean. Measured here (still tank, 2 ranks, both busy):
// each rank waits 3-10 % of the step for the other, where equal predicted work gives no wait.
#include <cmath>
#include <span>
#include <vector>

namespace sphperf::model {

// E[max_r X_r] for independent X_r ~ N(mean_r, sd_r^2); sd_r = 0 is a constant. Throws
// std::invalid_argument for empty, mismatched, negative or non-finite input.
double expected_max(std::span<const double> mean, std::span<const double> sd);

// An interval whose ranks all computed: per rank, compute and communication seconds per step.
struct BusyInterval {
    double steps = 0;
    std::vector<double> compute_s, comm_s;
};
// The noise of a step of compute c: standard deviation k sqrt(c). Interruptions (other
// processes, interrupts, a core slowed by its neighbour) arrive at random moments, so their
// count in a step, and the delay they add, has a variance that grows with the step's length:
// the standard deviation grows as its square root, not in proportion to it. Measured: half-scale
// still tanks on 2 ranks waited 3-25 % of their compute for each other, scale 1 runs 1-8 %.
inline double jitter_sd(double k_sqrt_s, double compute_s) {
    return k_sqrt_s * std::sqrt(compute_s);
}
// The wait summed over ranks and steps when each rank's compute per step has standard deviation
// jitter_sd(k, compute) and every step lasts the expected maximum of compute + communication.
double modelled_wait(std::span<const BusyInterval> intervals, double k_sqrt_s);
inline constexpr double jitter_k_max_sqrt_s = 1;
// The k in [0, jitter_k_max_sqrt_s] whose modelled wait equals the measured one: 0 when the
// intervals' own imbalance already accounts for it, the bound when even that is short.
double fit_jitter(std::span<const BusyInterval> intervals, double measured_wait_s);

} // namespace sphperf::model
