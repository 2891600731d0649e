#pragma once
// The host's speed, measured inside a run. On a VM whose cores are shared with other guests the
// same run takes 10-40 % more or less from one minute to the next (model/NOTES.md, session 46),
// and a reference run before a validation run does not see it (the speed does not hold for
// 3 s). A fixed piece of the density pass's arithmetic, run every few steps on every thread,
// does: its time tracks the run's own cost per step (model/NOTES.md, session 50), so the model
// can put calibration runs at one reference speed and say how much of a miss was the host's.
// Its reading also follows the vector width of the code before it (an Intel core's AVX-512
// frequency levels): on the 512-bit build it reads 3-9 % faster in Cell+Sorted runs than in
// Cell+Table runs (model/NOTES.md, session 58).
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace sphperf::sph {

// A fixed synthetic neighbourhood (deterministic): particles with velocities and masses, and
// `pairs` packed candidates (an index and a separation within the support of h = 1).
struct GaugeData {
    std::vector<double> vx, vy, mass;
    std::vector<std::uint32_t> index;
    std::vector<double> dx, dy;
};
GaugeData make_gauge_data(std::size_t particles, std::size_t pairs);

// The kernel: the continuity pair term (Cell+Sorted's packed loop: gathered neighbour fields,
// square root, kernel slope, division) summed over the packed pairs in groups of 64, each
// group one particle's; returns the sum (a checksum that keeps the work from being optimised
// away, the same on every machine up to rounding).
double gauge_kernel(std::span<const double> vx, std::span<const double> vy,
                    std::span<const double> mass, std::span<const std::uint32_t> index,
                    std::span<const double> dx, std::span<const double> dy);

// Runs the kernel on every thread of an OpenMP team at once and times each by its thread CPU
// time (what it computed, not the time it was descheduled: above the cores a rank shares its
// core). The data is made once and only read, shared by the threads. Each sample first runs
// the kernel once untimed: the run's own steps leave the caches in a state that depends on its
// size, and a cold start made a larger run's gauge read slower (session 50: scale-1 runs 5-25 %
// above the small calibration runs in one quick job); warm, the 28 KB stay in L1.
class SpeedGauge {
public:
    // 1024 pairs over 512 particles run 16 times: about 50-70 us here, 0.2 % of a 2.5 ms step
    // when sampled every 10 steps.
    static constexpr std::size_t default_pairs = 1024;
    static constexpr std::size_t particles = 512;
    static constexpr int default_repeats = 16;
    explicit SpeedGauge(std::size_t pairs = default_pairs, int repeats = default_repeats);
    // Mean over the team's threads of one sample's CPU seconds (`repeats` kernel runs, after
    // one untimed).
    double sample();
    // Pair terms one sample computes per thread.
    std::size_t pairs_per_sample() const { return pairs_ * static_cast<std::size_t>(repeats_); }
    double checksum() const { return checksum_; } // of the last sample, thread 0's

private:
    std::size_t pairs_;
    int repeats_;
    GaugeData data_;
    double checksum_ = 0;
};

// The round trip of a cache line between two threads of the team, measured inside a run. This
// VM's two vCPUs switch, in spells of seconds to minutes, between about 60 and 350 ns a round
// trip (sph/NOTES.md, sessions 21 and 70), and a step at 2 threads pays it at every parallel
// region, barrier and line the other thread wrote: in the far spells the grid update and the
// kicks of a Cell+Sorted dam break cost about twice as much. Sampled beside the speed gauge:
// threads 0 and 1 pass one line back and forth, and the report says which spell each interval
// ran in.
class CoreLatencyGauge {
public:
    // Round trips timed together (a clock read here costs a good part of one) and batches per
    // sample: 5 x 8, about 3 us in the near spells, 15 us in the far ones.
    static constexpr int round_trips_per_batch = 8;
    static constexpr int default_batches = 5;
    // A wait longer than this ends the sample without a reading: the partner thread is not
    // running (more threads than cores), and spinning on would cost a time slice each.
    static constexpr double timeout_s = 50e-6;
    explicit CoreLatencyGauge(int batches = default_batches);
    // Seconds: the median over the batches of the mean round trip between threads 0 and 1 of
    // an OpenMP team, or a NaN for a team of one thread or a sample cut short by the timeout.
    double sample();

private:
    int batches_;
    struct alignas(64) Line {
        std::atomic<std::uint32_t> value{0};
        std::atomic<bool> abandoned{false};
    };
    Line line_;
    std::vector<double> times_; // the last sample's batch means
};

} // namespace sphperf::sph
