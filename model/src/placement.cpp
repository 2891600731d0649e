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

namespace {
// One MPI_Sendrecv of the app's exchanges: send to `to`, then wait for `from` (-1: none).
struct Call {
    int to, from;
    bool comm; // transfers (comm) or handshake (wait)
};
} // namespace

ReplayedStep replay_time_shared(const std::vector<std::array<double, 3>> &cpu_s, int cores,
                                double slice_s, int steps, double tick_s) {
    if (cores < 1)
        throw std::invalid_argument("replay_time_shared: expected cores >= 1");
    std::vector<int> core_of(cpu_s.size());
    for (std::size_t r = 0; r < core_of.size(); ++r)
        core_of[r] = static_cast<int>(r) % cores;
    return replay_time_shared(cpu_s, core_of, slice_s, steps, tick_s);
}

ReplayedStep replay_time_shared(const std::vector<std::array<double, 3>> &cpu_s,
                                const std::vector<int> &core_of, double slice_s, int steps,
                                double tick_s) {
    const int P = static_cast<int>(cpu_s.size());
    if (P < 1 || core_of.size() != cpu_s.size() ||
        std::any_of(core_of.begin(), core_of.end(), [](int c) { return c < 0; }) ||
        !(slice_s > 0) || !(tick_s > 0) || steps < 3)
        throw std::invalid_argument("replay_time_shared: expected ranks >= 1, a core index >= 0 "
                                    "per rank, a slice and a tick > 0 and steps >= 3");
    const int cores = *std::max_element(core_of.begin(), core_of.end()) + 1;
    constexpr int warm = 2;
    // Per rank the ops of one step: compute segment k (call index -1), then its exchange k.
    struct Op {
        int segment; // >= 0: compute; -1: a call
        Call call;
        int shift; // the exchange a call belongs to
    };
    std::vector<std::vector<Op>> prog(static_cast<std::size_t>(P));
    for (int r = 0; r < P; ++r) {
        const int west = r > 0 ? r - 1 : -1, east = r + 1 < P ? r + 1 : -1;
        auto &ops = prog[static_cast<std::size_t>(r)];
        for (int k = 0; k < 3; ++k) {
            ops.push_back({k, {}, k});
            ops.push_back({-1, {east, west, false}, k});
            ops.push_back({-1, {west, east, false}, k});
            for (int i = 0; i < 2; ++i)
                ops.push_back({-1, {east, west, true}, k});
            for (int i = 0; i < 2; ++i)
                ops.push_back({-1, {west, east, true}, k});
        }
    }
    const std::size_t nops = prog[0].size();
    auto idx = [P](int from, int to) { return static_cast<std::size_t>(from * P + to); };
    std::vector<long> sent(static_cast<std::size_t>(P * P), 0), got(sent.size(), 0);
    std::vector<std::size_t> pc(static_cast<std::size_t>(P), 0);
    std::vector<int> step(static_cast<std::size_t>(P), 0);
    std::vector<double> left(static_cast<std::size_t>(P), -1);
    std::vector<char> posted(static_cast<std::size_t>(P), 0);
    std::vector<std::vector<int>> on_core(static_cast<std::size_t>(cores));
    for (int r = 0; r < P; ++r)
        on_core[static_cast<std::size_t>(core_of[static_cast<std::size_t>(r)])].push_back(r);
    std::vector<int> running(static_cast<std::size_t>(cores), -1);
    std::vector<double> held(static_cast<std::size_t>(cores), 0);
    for (int c = 0; c < cores; ++c)
        if (!on_core[static_cast<std::size_t>(c)].empty())
            running[static_cast<std::size_t>(c)] = on_core[static_cast<std::size_t>(c)][0];
    ReplayedStep out;
    out.wait_s.assign(static_cast<std::size_t>(P), 0);
    out.comm_s.assign(static_cast<std::size_t>(P), 0);
    out.shift_comm_s.assign(static_cast<std::size_t>(P), {0.0, 0.0, 0.0});
    // Runs rank r for up to `budget` seconds of CPU; true when it gives its core away.
    auto run = [&](int r, double budget) {
        const auto u = static_cast<std::size_t>(r);
        double spent = 0;
        while (step[u] < steps) {
            const Op &op = prog[u][pc[u]];
            if (op.segment >= 0) {
                if (left[u] < 0)
                    left[u] = cpu_s[u][static_cast<std::size_t>(op.segment)];
                const double take = std::min(left[u], budget - spent);
                left[u] -= take;
                spent += take;
                if (left[u] > 1e-12)
                    return false;
                left[u] = -1;
            } else {
                if (!posted[u]) {
                    if (op.call.to >= 0)
                        ++sent[idx(r, op.call.to)];
                    posted[u] = 1;
                }
                if (op.call.from >= 0) {
                    if (got[idx(op.call.from, r)] >= sent[idx(op.call.from, r)])
                        return true; // nothing there: it yields
                    ++got[idx(op.call.from, r)];
                }
                posted[u] = 0;
            }
            if (++pc[u] == nops) {
                pc[u] = 0;
                ++step[u];
            }
            if (spent >= budget)
                return false;
        }
        return true;
    };
    double t = 0, t_start = -1;
    auto all_past = [&](int s) {
        return std::all_of(step.begin(), step.end(), [s](int x) { return x >= s; });
    };
    while (!all_past(steps)) {
        for (int c = 0; c < cores; ++c) {
            const auto cu = static_cast<std::size_t>(c);
            const int r = running[cu];
            if (r < 0)
                continue;
            const bool yielded = run(r, tick_s);
            held[cu] += tick_s;
            const auto &mine = on_core[cu];
            if (mine.size() > 1 && (yielded || held[cu] >= slice_s)) {
                const auto at = std::find(mine.begin(), mine.end(), r) - mine.begin();
                running[cu] = mine[static_cast<std::size_t>(at + 1) % mine.size()];
                held[cu] = 0;
            }
        }
        t += tick_s;
        if (t_start < 0 && all_past(warm)) {
            t_start = t;
            std::fill(out.wait_s.begin(), out.wait_s.end(), 0.0);
            std::fill(out.comm_s.begin(), out.comm_s.end(), 0.0);
            std::fill(out.shift_comm_s.begin(), out.shift_comm_s.end(),
                      std::array<double, 3>{0.0, 0.0, 0.0});
        }
        for (int r = 0; r < P; ++r) {
            const auto u = static_cast<std::size_t>(r);
            if (step[u] >= steps)
                continue;
            const Op &op = prog[u][pc[u]];
            if (op.segment >= 0)
                continue;
            (op.call.comm ? out.comm_s : out.wait_s)[u] += tick_s;
            if (op.call.comm)
                out.shift_comm_s[u][static_cast<std::size_t>(op.shift)] += tick_s;
        }
    }
    const double n = steps - warm;
    for (auto *v : {&out.wait_s, &out.comm_s})
        for (double &x : *v)
            x /= n;
    for (auto &a : out.shift_comm_s)
        for (double &x : a)
            x /= n;
    out.step_s = (t - t_start) / n;
    return out;
}

double sharing_bubble_phi(std::span<const double> compute_s, std::span<const int> core_of) {
    if (compute_s.size() != core_of.size() ||
        std::any_of(core_of.begin(), core_of.end(), [](int c) { return c < 0; }))
        throw std::invalid_argument(
            "sharing_bubble_phi: expected one core index >= 0 per rank's compute");
    std::map<int, std::pair<double, double>> top; // core -> (busiest, second busiest)
    for (std::size_t r = 0; r < compute_s.size(); ++r) {
        auto &[first, second] = top[core_of[r]];
        const double c = std::max(0.0, compute_s[r]);
        if (c > first) {
            second = first;
            first = c;
        } else {
            second = std::max(second, c);
        }
    }
    if (top.empty())
        return 0.0;
    double phi = 1.0;
    for (const auto &[core, t] : top)
        phi = std::min(phi, t.first > 0 ? t.second / t.first : 0.0);
    return phi;
}

} // namespace sphperf::model
