#pragma once
// Named phase timers with RAII scopes.
#include "sphperf/timer.hpp"

#include <array>
#include <cstddef>
#include <string_view>

namespace sphperf::sph {

// comm is the MPI transfer alone (what the Hockney model predicts), wait the time spent
// waiting for a slower neighbour before each exchange, pack the selection and copying of the
// particles that cross: three terms the performance model validates one by one.
enum class Phase : std::size_t {
    pairs,
    grid,
    comp,
    comm,
    wait,
    pack,
    boundary,
    integrate,
    output,
    idsort,    // Cell+List / Cell+Table: ordering each neighbour list by id (not grid cost)
    rebalance, // balanced slabs: the re-cut and its migrations, all in one (no other phase)
    gauge,     // the speed gauge (gauge.hpp), every --speed-gauge-every steps
    count
};

inline constexpr std::array<std::string_view, static_cast<std::size_t>(Phase::count)> phase_keys{
    "pairs_s",    "grid_s",      "comp_s",   "comm_s",   "wait_s",      "pack_s",
    "boundary_s", "integrate_s", "output_s", "idsort_s", "rebalance_s", "gauge_s"};

// The comm phase by exchange, in the order of a step: the transfers of each are predicted and
// validated apart, since what a shift costs on one node depends on what ran before it.
enum class Shift : std::size_t { migration, ghosts, densities, count };
inline constexpr std::array<std::string_view, static_cast<std::size_t>(Shift::count)> shift_keys{
    "migration", "ghosts", "densities"};
using ShiftTimes = std::array<double, static_cast<std::size_t>(Shift::count)>;

class PhaseTimers {
public:
    void add(Phase p, double seconds) { acc_[static_cast<std::size_t>(p)] += seconds; }
    double operator[](Phase p) const { return acc_[static_cast<std::size_t>(p)]; }
    const auto &values() const { return acc_; }
    void reset() { acc_.fill(0.0); }

private:
    std::array<double, static_cast<std::size_t>(Phase::count)> acc_{};
};

class ScopedPhase {
public:
    ScopedPhase(PhaseTimers &t, Phase p) : timers_(t), phase_(p), start_(wall_seconds()) {}
    ~ScopedPhase() { timers_.add(phase_, wall_seconds() - start_); }
    ScopedPhase(const ScopedPhase &) = delete;
    ScopedPhase &operator=(const ScopedPhase &) = delete;

private:
    PhaseTimers &timers_;
    Phase phase_;
    double start_;
};

} // namespace sphperf::sph
