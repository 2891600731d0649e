#include "stream_width.hpp"

namespace sphperf::stream {

namespace w128 {
KernelSet kernel_set();
}
namespace w256 {
KernelSet kernel_set();
}
namespace w512 {
KernelSet kernel_set();
}

std::vector<KernelSet> available_kernel_sets() {
    std::vector<KernelSet> sets{w128::kernel_set()};
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"))
        sets.push_back(w256::kernel_set());
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl"))
        sets.push_back(w512::kernel_set());
    return sets;
}

} // namespace sphperf::stream
