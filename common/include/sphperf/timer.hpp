#pragma once
#include <chrono>
#include <ctime>

namespace sphperf {

// Monotonic wall clock in seconds.
inline double wall_seconds() {
    using clock = std::chrono::steady_clock;
    return std::chrono::duration<double>(clock::now().time_since_epoch()).count();
}

// CPU time of the calling thread in seconds: what it computed, not the time it was descheduled
// (the time-shared replay's input, sph/README.md).
inline double thread_cpu_seconds() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

} // namespace sphperf
