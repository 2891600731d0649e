#include "sphperf/model/comm_model.hpp"

#include "sphperf/cli.hpp"

#include <algorithm>
#include <cmath>

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
    for (std::size_t i = 1; i < m.classes_.size(); ++i)
        if (m.classes_[i].fit.predict(probe_bytes) >
            m.classes_[m.slowest_].fit.predict(probe_bytes))
            m.slowest_ = i;
    return m;
}

const Link &CommModel::link(int pu_a, int pu_b) const {
    if (pu_a >= 0 && pu_b >= 0 && pu_a != pu_b)
        for (const auto &l : pairs_)
            if ((l.pu_a == pu_a && l.pu_b == pu_b) || (l.pu_a == pu_b && l.pu_b == pu_a))
                return l;
    return slowest_class();
}

double CommModel::sendrecv_seconds(int pu, int pu_out, double out, int pu_in, double in) const {
    const double t_out = out >= 0 ? seconds(pu, pu_out, out) : 0.0;
    const double t_in = in >= 0 ? seconds(pu_in, pu, in) : 0.0;
    return std::max(t_out, t_in);
}

} // namespace sphperf::model
