#include "sphperf/model/comm_model.hpp"

#include "sphperf/errors.hpp"
#include "sphperf/model/interpolate.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <tuple>

namespace sphperf::model {

namespace {
constexpr double probe_bytes = 16384; // ranks classes by a typical ghost message

double number(const nlohmann::json &j, const char *key, const std::string &where) {
    if (!j.is_object() || !j.contains(key) || !j[key].is_number() ||
        !std::isfinite(j[key].get<double>()))
        throw UsageError(where + " lacks the finite number \"" + key + "\"");
    return j[key].get<double>();
}
} // namespace

nlohmann::json to_json(const PiecewiseFit &fit) {
    nlohmann::json pieces = nlohmann::json::array();
    for (const auto &p : fit.pieces)
        pieces.push_back({{"alpha_s", p.alpha_s},
                          {"beta_s_per_byte", p.beta_s_per_byte},
                          {"first_bytes", p.first_bytes},
                          {"last_bytes", p.last_bytes},
                          {"r2", p.r2}});
    return {{"breakpoint_bytes", fit.breakpoint_bytes}, {"pieces", pieces}, {"r2", fit.r2}};
}

PiecewiseFit piecewise_from_json(const nlohmann::json &j, const std::string &where) {
    PiecewiseFit f;
    f.breakpoint_bytes = number(j, "breakpoint_bytes", where);
    if (!j.contains("pieces") || !j["pieces"].is_array() || j["pieces"].empty() ||
        j["pieces"].size() > 2)
        throw UsageError(where + " needs \"pieces\": an array of 1 or 2 Hockney lines");
    for (const auto &p : j["pieces"]) {
        LineFit l;
        l.alpha_s = number(p, "alpha_s", where + "/pieces");
        l.beta_s_per_byte = number(p, "beta_s_per_byte", where + "/pieces");
        l.first_bytes = p.value("first_bytes", 0.0);
        l.last_bytes = p.value("last_bytes", 0.0);
        l.r2 = p.value("r2", 0.0);
        f.pieces.push_back(l);
    }
    f.single = f.pieces.front();
    f.r2 = j.value("r2", 0.0);
    return f;
}

CommModel CommModel::from_profile(const nlohmann::json &machine) {
    if (!machine.contains("hockney") || !machine["hockney"].is_object())
        throw UsageError("machine profile lacks the \"hockney\" section (made by an older "
                         "machine-profile: run scripts/characterise-node.sh again)");
    const auto &h = machine["hockney"];
    CommModel m;
    for (const auto &p : h.value("pairs", nlohmann::json::array())) {
        Link l;
        l.locality = p.value("locality", "unknown");
        const auto pus = p.value("pus", nlohmann::json::array());
        if (pus.size() == 2 && pus[0].is_number_integer() && pus[1].is_number_integer()) {
            l.pu_a = pus[0].get<int>();
            l.pu_b = pus[1].get<int>();
        }
        l.fit = piecewise_from_json(p, "machine profile hockney/pairs");
        m.pairs_.push_back(std::move(l));
    }
    if (!h.contains("classes") || !h["classes"].is_object() || h["classes"].empty())
        throw UsageError("machine profile hockney/classes is missing or empty");
    for (const auto &[name, c] : h["classes"].items()) {
        Link l;
        l.locality = name;
        l.fit = piecewise_from_json(c, "machine profile hockney/classes/" + name);
        m.classes_.push_back(std::move(l));
    }
    // The fallback for an unknown placement on one node: the slowest class within a node
    // (other_node only when nothing else was measured).
    auto rank = [&](std::size_t i) {
        return std::pair{m.classes_[i].locality != "other_node",
                         m.classes_[i].fit.predict(probe_bytes)};
    };
    for (std::size_t i = 1; i < m.classes_.size(); ++i)
        if (rank(i) > rank(m.slowest_))
            m.slowest_ = i;
    return m;
}

const Link &CommModel::link(int pu_a, int pu_b) const {
    if (pu_a >= 0 && pu_b >= 0 && pu_a != pu_b)
        for (const auto &l : pairs_)
            if (l.locality != "other_node" &&
                ((l.pu_a == pu_a && l.pu_b == pu_b) || (l.pu_a == pu_b && l.pu_b == pu_a)))
                return l;
    return slowest_class();
}

const Link *CommModel::class_named(const std::string &name) const {
    for (const auto &l : classes_)
        if (l.locality == name)
            return &l;
    return nullptr;
}

double CommModel::sendrecv_seconds(int pu, int pu_out, double out, int pu_in, double in) const {
    const double t_out = out >= 0 ? seconds(pu, pu_out, out) : 0.0;
    const double t_in = in >= 0 ? seconds(pu_in, pu, in) : 0.0;
    return std::max(t_out, t_in);
}

ExchangeModel ExchangeModel::from_profile(const nlohmann::json &machine) {
    ExchangeModel m;
    if (!machine.contains("exchange"))
        return m;
    const auto &e = machine["exchange"];
    if (!e.is_array())
        throw UsageError("machine profile \"exchange\" is not an array of exchange reports");
    for (const auto &r : e) {
        ExchangeSet s;
        const std::string where = "machine profile exchange";
        s.ranks = static_cast<int>(number(r, "ranks", where));
        s.cores = static_cast<int>(number(r, "cores", where));
        if (s.ranks < 2 || s.cores < 1)
            throw UsageError(where + " has " + std::to_string(s.ranks) + " ranks on " +
                             std::to_string(s.cores) + " cores (expected >= 2 and >= 1)");
        if (!r.contains("points") || !r["points"].is_array() || r["points"].empty())
            throw UsageError(where + " at " + std::to_string(s.ranks) +
                             " ranks lacks a non-empty \"points\" array");
        for (const auto &p : r["points"]) {
            ExchangePoint x;
            x.gap_s = number(p, "gap_s_mean", where + "/points");
            x.bytes = number(p, "payload_bytes", where + "/points");
            x.mean_s =
                number(p.value("shift", nlohmann::json()), "mean_s", where + "/points/shift");
            x.median_s = p["shift"].value("median_s", x.mean_s);
            const bool overlapped = p.value("overlapped", false);
            const bool follows = p.value("follows_shift", false);
            if (overlapped && follows)
                throw UsageError(where + " has a point both overlapped and following a shift");
            x.mode = overlapped ? ShiftMode::overlapped
                     : follows  ? ShiftMode::following
                                : ShiftMode::blocking;
            if (p.contains("round_overhead") && p["round_overhead"].is_number())
                x.overhead = p["round_overhead"].get<double>();
            if (x.gap_s < 0 || x.bytes <= 0 || x.mean_s < 0)
                throw UsageError(where + " has a point with a negative gap or cost, or no payload");
            s.points.push_back(x);
        }
        if (!s.has(ShiftMode::blocking))
            throw UsageError(where + " at " + std::to_string(s.ranks) +
                             " ranks has overlapped or following points only (expected "
                             "blocking ones too)");
        std::sort(s.points.begin(), s.points.end(), [](const auto &a, const auto &b) {
            return std::tie(a.mode, a.bytes, a.gap_s) < std::tie(b.mode, b.bytes, b.gap_s);
        });
        s.tables = std::make_shared<const ShiftTables>(ShiftTables::of(s.points));
        m.sets_.push_back(std::move(s));
    }
    return m;
}

const ExchangeSet &ExchangeModel::set_for(int ranks, int threads, int cores) const {
    if (sets_.empty())
        throw UsageError("the machine profile has no exchange measurements");
    const double load = static_cast<double>(ranks) * threads / cores;
    const ExchangeSet *best = &sets_.front();
    auto distance = [&](const ExchangeSet &s) {
        // Within the cores one rank count is as good as another: prefer the largest measured.
        if (load <= 1 && s.load() <= 1)
            return -s.load() * 1e-6;
        return std::abs(std::log(s.load()) - std::log(load));
    };
    for (const auto &s : sets_)
        if (distance(s) < distance(*best))
            best = &s;
    return *best;
}

namespace {
constexpr double smallest_gap_s = 1e-7; // gaps below a tenth of a microsecond are the same
// A shift this close after another, relative to the step, follows it (app_shift_seconds).
constexpr double follows_within = 0.1;

const char *mode_name(ShiftMode mode) {
    switch (mode) {
    case ShiftMode::following:
        return "following";
    case ShiftMode::overlapped:
        return "overlapped";
    default:
        return "blocking";
    }
}

} // namespace

ShiftTables ShiftTables::of(const std::vector<ExchangePoint> &points) {
    ShiftTables t;
    for (const auto &p : points) {
        // A payload joins its mode's list when it differs from the one before (the points are
        // sorted by mode, payload and gap); its curve holds every point of that payload.
        auto &curves = t.by_mode[static_cast<std::size_t>(p.mode)];
        if (!curves.empty() && curves.back().bytes == p.bytes)
            continue;
        ShiftTables::Curve c{p.bytes, {}};
        for (const auto &q : points)
            if (q.bytes == p.bytes && q.mode == p.mode)
                c.log_gap_mean.emplace_back(std::log(std::max(q.gap_s, smallest_gap_s)), q.mean_s);
        std::sort(c.log_gap_mean.begin(), c.log_gap_mean.end());
        curves.push_back(std::move(c));
    }
    return t;
}

namespace {
// Mean seconds of one shift after gap_s carrying `bytes` (ExchangeModel::shift_seconds).
double shift_seconds_in(const ShiftTables &t, double gap_s, double bytes, ShiftMode mode) {
    const auto &curves = t.by_mode[static_cast<std::size_t>(mode)];
    if (curves.empty())
        throw std::logic_error(std::string("exchange set without ") + mode_name(mode) + " points");
    const double log_gap = std::log(std::max(gap_s, smallest_gap_s));
    auto at = [&](std::size_t k) { return interpolate(curves[k].log_gap_mean, log_gap); };
    if (curves.size() == 1 || bytes <= curves.front().bytes)
        return at(0);
    std::size_t hi = 1;
    while (hi + 1 < curves.size() && bytes > curves[hi].bytes)
        ++hi;
    const double b0 = curves[hi - 1].bytes, b1 = curves[hi].bytes;
    const double y0 = at(hi - 1), y1 = at(hi);
    // Beyond the largest payload the last slope goes on (never downward).
    const double slope = std::max(0.0, (y1 - y0) / (b1 - b0));
    return bytes <= b1 ? y0 + (y1 - y0) * (bytes - b0) / (b1 - b0) : y1 + slope * (bytes - b1);
}
} // namespace

double ExchangeModel::shift_seconds(const ExchangeSet &set, double gap_s, double bytes,
                                    ShiftMode mode) {
    return set.tables ? shift_seconds_in(*set.tables, gap_s, bytes, mode)
                      : shift_seconds_in(ShiftTables::of(set.points), gap_s, bytes, mode);
}

double ExchangeModel::app_shift_seconds(const ExchangeSet &set, double since_any_s,
                                        double since_kind_s, double bytes, GapRule rule) {
    const bool follows = since_any_s < follows_within * since_kind_s;
    if (set.load() > 1)
        return shift_seconds(set, since_any_s, bytes);
    if (!follows)
        return shift_seconds(set, rule == GapRule::any_shift ? since_any_s : since_kind_s, bytes);
    return shift_seconds(set, since_kind_s, bytes,
                         set.has(ShiftMode::following) ? ShiftMode::following
                                                       : ShiftMode::blocking);
}

double ExchangeModel::round_overhead(const ExchangeSet &set, double gap_s) {
    if (set.load() <= 1)
        return 1.0;
    // Every payload's points together: the overhead hardly depends on the payload.
    std::vector<std::pair<double, double>> xy;
    for (const auto &p : set.points)
        if (p.overhead > 0 && p.mode == ShiftMode::blocking)
            xy.emplace_back(std::log(std::max(p.gap_s, smallest_gap_s)), p.overhead);
    if (xy.empty())
        return 1.0;
    std::sort(xy.begin(), xy.end());
    return std::max(1.0, interpolate(xy, std::log(std::max(gap_s, smallest_gap_s))));
}

} // namespace sphperf::model
