#include "sphperf/model/placement.hpp"

#include <algorithm>
#include <map>
#include <stdexcept>

namespace sphperf::model {

std::vector<int> launcher_placement(int ranks, int threads, int cores) {
    if (ranks < 1 || threads < 1 || cores < 1)
        throw std::invalid_argument("launcher_placement: ranks, threads and cores must be >= 1");
    std::vector<int> pus(static_cast<std::size_t>(ranks), -1);
    for (int r = 0; r < ranks; ++r)
        if (ranks * threads <= cores)
            pus[static_cast<std::size_t>(r)] = r * threads;
        else if (threads == 1)
            pus[static_cast<std::size_t>(r)] = r % cores;
    return pus;
}

SharedStep time_shared_step(std::span<const double> compute_s, std::span<const double> field,
                            std::span<const int> pus, int threads, int cores, double overhead) {
    if (field.size() != compute_s.size() || pus.size() != compute_s.size())
        throw std::invalid_argument(
            "time_shared_step: compute, field and placement differ in length");
    SharedStep out;
    if (compute_s.empty())
        return out;
    const bool bound = std::all_of(pus.begin(), pus.end(), [](int p) { return p >= 0; });
    if (bound) {
        std::map<int, std::pair<double, int>> per_unit; // pu -> (compute, busy ranks)
        for (std::size_t r = 0; r < compute_s.size(); ++r) {
            auto &u = per_unit[pus[r]];
            u.first += compute_s[r];
            u.second += field[r] > 0 ? 1 : 0;
        }
        for (const auto &[pu, u] : per_unit) {
            const bool shared = u.second >= 2;
            out.shared_core = out.shared_core || shared;
            out.step_s = std::max(out.step_s, u.first * (shared ? overhead : 1.0));
        }
        return out;
    }
    double demand = 0, slowest = 0;
    for (double c : compute_s) {
        demand += c * threads;
        slowest = std::max(slowest, c);
    }
    const double spread = demand / std::max(cores, 1);
    out.shared_core = spread > slowest;
    out.step_s = std::max(slowest, spread * overhead);
    return out;
}

std::optional<LinearFit> fit_sharing_overhead(std::span<const double> compute_per_step_s,
                                              std::span<const double> overhead_per_step_s,
                                              double min_span) {
    if (compute_per_step_s.size() != overhead_per_step_s.size())
        throw std::invalid_argument("fit_sharing_overhead: compute and overhead differ in length");
    if (compute_per_step_s.size() < 3)
        return std::nullopt;
    const auto [lo, hi] = std::minmax_element(compute_per_step_s.begin(), compute_per_step_s.end());
    if (!(*lo > 0) || *hi < min_span * *lo)
        return std::nullopt;
    std::vector<std::vector<double>> X;
    for (double c : compute_per_step_s)
        X.push_back({1.0, c});
    return fit_linear(X, overhead_per_step_s, {"const", "shared_compute"});
}

} // namespace sphperf::model
