#pragma once
// Step-to-step jitter of the ranks' compute. The exchange is blocking, so every step lasts as long
// as its slowest rank: with equal work on every rank the step still costs the expected maximum
// of their noisy compute times, not their mean. Measured here (still tank, 2 ranks, both busy):
// each rank waits 3-10 % of the step for the other, where equal predicted work gives no wait.
#include <cmath>
#include <span>
#include <string_view>
#include <vector>

namespace sphperf::model {

// E[max_r X_r] for independent X_r ~ N(mean_r, sd_r^2); sd_r = 0 is a constant. Throws
// std::invalid_argument for empty, mismatched, negative or non-finite input.
double expected_max(std::span<const double> mean, std::span<const double> sd);

// How a rank's compute noise per step grows with the step's compute c, two hosts' evidence:
// - sqrt: standard deviation k sqrt(c), k in s^0.5. Interruptions (other processes,
//   interrupts) that arrive at random moments: their delay's variance grows with the step's
//   length. Sessions 13-15's host: half-scale still tanks on 2 ranks waited 3-25 % of their
//   compute for each other, scale-1 runs 1-8 %.
// - proportional: standard deviation k c, k a fraction of the step. A core whose speed
//   changes in spells of seconds, hundreds of steps, independently of its neighbour: the late
//   rank is late by a share of its step. Session 61's host: still tanks on 2 ranks waited 8 %
//   of their compute at 1.8-25 ms steps alike (model/NOTES.md).
enum class JitterForm { sqrt, proportional };
std::string_view to_string(JitterForm form);
struct Jitter {
    JitterForm form = JitterForm::sqrt;
    double k = 0; // s^0.5 (sqrt) or a fraction of the step (proportional); 0: none
};
inline double jitter_sd(Jitter j, double compute_s) {
    return j.form == JitterForm::sqrt ? j.k * std::sqrt(compute_s) : j.k * compute_s;
}

// An interval whose ranks all computed: per rank, compute and communication seconds per step.
struct BusyInterval {
    double steps = 0;
    std::vector<double> compute_s, comm_s;
};
// The wait summed over ranks and steps when each rank's compute per step has standard deviation
// jitter_sd(j, compute) and every step lasts the expected maximum of compute + communication.
double modelled_wait(std::span<const BusyInterval> intervals, Jitter j);
// The largest k a fit returns, either form (1 s^0.5: 3 ms on a 10 us step; 1: a whole step).
inline constexpr double jitter_k_max = 1;
// The k in [0, jitter_k_max] whose modelled wait equals the measured one: 0 when the
// intervals' own imbalance already accounts for it, the bound when even that is short.
double fit_jitter(std::span<const BusyInterval> intervals, double measured_wait_s, JitterForm form);

// One calibration run's all-busy intervals and what it measured over them: the wait summed over
// ranks and steps, and the ranks' summed time (compute + communication + wait), the scale of
// its error.
struct WaitRun {
    std::vector<BusyInterval> busy;
    double measured_wait_s = 0, measured_time_s = 0;
};
// Leave one run out: each run's wait predicted with the median of the other runs' k (k[i],
// fit_jitter of run i in this form), its error over the run's time; the root mean square over
// the runs. NaN with fewer than 3 runs (no median of 2 others); std::invalid_argument when k
// does not hold one value per run.
double jitter_cv_rms(std::span<const WaitRun> runs, std::span<const double> k, JitterForm form);

} // namespace sphperf::model
