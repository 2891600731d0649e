#pragma once
#include <chrono>

namespace sphperf {

// Monotonic wall clock in seconds.
inline double wall_seconds() {
    using clock = std::chrono::steady_clock;
    return std::chrono::duration<double>(clock::now().time_since_epoch()).count();
}

} // namespace sphperf
