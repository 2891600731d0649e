#include "sphperf/model/profile.hpp"

#include "sphperf/errors.hpp"
#include "sphperf/model/comm_model.hpp"

#include <cmath>
#include <fstream>
#include <map>
#include <stdexcept>

namespace sphperf::model {

nlohmann::json load_report(const std::filesystem::path &path, std::string_view benchmark) {
    std::ifstream in(path);
    if (!in)
        throw UsageError("cannot read " + std::string(benchmark) + " report '" + path.string() +
                         "'");
    nlohmann::json j;
    try {
        // parse(), not operator>>: the stream operator stops after the first value and would
        // accept a report followed by garbage.
        j = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception &e) {
        throw UsageError("'" + path.string() + "' is not valid JSON (" + e.what() + ")");
    }
    const auto kind = j.is_object() ? j.find("benchmark") : j.end();
    if (!j.is_object() || kind == j.end() || !kind->is_string() ||
        kind->get_ref<const std::string &>() != benchmark)
        throw UsageError("'" + path.string() + "' is not a report of kind \"" +
                         std::string(benchmark) + "\" (its \"benchmark\" field is " +
                         (j.is_object() && kind != j.end() ? kind->dump() : "missing") + ")");
    return j;
}

namespace {
// Typed reads at JSON pointers, each naming the file and the key when the value is absent, of
// the wrong type, not finite or out of range.
class Checked {
public:
    Checked(const nlohmann::json &root, std::string where)
        : root_(root), where_(std::move(where)) {}

    const nlohmann::json &at(const std::string &ptr) const {
        const nlohmann::json::json_pointer p(ptr);
        if (!root_.contains(p))
            fail(ptr, "is missing");
        return root_.at(p);
    }
    double number(const std::string &ptr, double min, bool strictly) const {
        const auto &v = at(ptr);
        if (!v.is_number())
            fail(ptr, "is " + v.dump() + ", expected a number");
        const double x = v.get<double>();
        if (!std::isfinite(x) || (strictly ? !(x > min) : !(x >= min)))
            fail(ptr, "is " + v.dump() + ", expected a finite number " + (strictly ? "> " : ">= ") +
                          nlohmann::json(min).dump());
        return x;
    }
    double positive(const std::string &ptr) const { return number(ptr, 0, true); }
    double finite(const std::string &ptr) const {
        const auto &v = at(ptr);
        if (!v.is_number() || !std::isfinite(v.get<double>()))
            fail(ptr, "is " + v.dump() + ", expected a finite number");
        return v.get<double>();
    }
    double non_negative(const std::string &ptr) const { return number(ptr, 0, false); }
    long long integer(const std::string &ptr, long long min, long long max) const {
        const auto &v = at(ptr);
        if (!v.is_number_integer() || v.get<long long>() < min || v.get<long long>() > max)
            fail(ptr, "is " + v.dump() + ", expected an integer in [" + std::to_string(min) + ", " +
                          std::to_string(max) + "]");
        return v.get<long long>();
    }
    std::size_t array(const std::string &ptr) const { // non-empty
        const auto &v = at(ptr);
        if (!v.is_array() || v.empty())
            fail(ptr, "is " + (v.is_array() ? std::string("empty") : v.dump()) +
                          ", expected a non-empty array");
        return v.size();
    }
    void string(const std::string &ptr) const {
        if (!at(ptr).is_string())
            fail(ptr, "is " + at(ptr).dump() + ", expected a string");
    }
    void object(const std::string &ptr) const {
        if (!at(ptr).is_object())
            fail(ptr, "is " + at(ptr).dump() + ", expected an object");
    }
    [[noreturn]] void fail(const std::string &ptr, const std::string &what) const {
        std::string shown = what.size() > 120 ? what.substr(0, 120) + "..." : what;
        throw UsageError(where_ + ": " + ptr + " " + shown);
    }

private:
    const nlohmann::json &root_;
    std::string where_;
};

std::string at_index(const std::string &base, std::size_t i) {
    return base + "/" + std::to_string(i);
}

double require_number(const nlohmann::json &j, const nlohmann::json::json_pointer &ptr,
                      std::string_view what) {
    if (!j.contains(ptr) || !j.at(ptr).is_number())
        throw UsageError(std::string(what) + " report lacks the number " + ptr.to_string());
    return j.at(ptr).get<double>();
}

nlohmann::json coretype_entry(const nlohmann::json &dgemm) {
    double best_fraction = 0;
    for (const auto &r : dgemm.value("results", nlohmann::json::array()))
        best_fraction = std::max(best_fraction, r.value("fraction_of_peak", 0.0));
    return {{"corename", dgemm.value("corename", "unknown")},
            {"coretype_env", dgemm.value("openblas_coretype_env", nlohmann::json())},
            {"best_gflops", dgemm.value("best_gflops", 0.0)},
            {"results", dgemm.value("results", nlohmann::json::array())}};
}
// Both Hockney pieces and the breakpoint of every measured pair, with the processing units
// its ranks ran on, and per locality class the slowest pair (at a 16 KiB message, a typical
// ghost exchange): the thesis' "maximum average" choice, here per piece.
nlohmann::json hockney_section(const nlohmann::json &pingpong) {
    std::map<int, int> pu_of_rank;
    for (const auto &r : pingpong.value("rank_placement", nlohmann::json::array()))
        if (r.contains("rank") && r.contains("last_cpu") && r.value("bound_to_one_core", false))
            pu_of_rank[r["rank"].get<int>()] = r["last_cpu"].get<int>();
    nlohmann::json pairs = nlohmann::json::array(), classes = nlohmann::json::object();
    std::map<std::string, double> slowest;
    for (const auto &pr : pingpong.value("pairs", nlohmann::json::array())) {
        if (!pr.contains("pieces"))
            continue;
        nlohmann::json e = pr;
        e.erase("samples");
        const auto ranks = pr.value("ranks", nlohmann::json::array());
        const std::string loc = pr.value("locality", "unknown");
        // Processing units identify a link only within one node.
        if (loc != "other_node" && ranks.size() == 2 && pu_of_rank.count(ranks[0].get<int>()) &&
            pu_of_rank.count(ranks[1].get<int>()))
            e["pus"] = {pu_of_rank[ranks[0].get<int>()], pu_of_rank[ranks[1].get<int>()]};
        const PiecewiseFit fit = piecewise_from_json(e, "pingpong pair");
        const double t = fit.predict(16384.0);
        if (!slowest.count(loc) || t > slowest[loc]) {
            slowest[loc] = t;
            classes[loc] = to_json(fit);
            classes[loc]["from_ranks"] = ranks;
        }
        pairs.push_back(std::move(e));
    }
    return {{"pairs", pairs}, {"classes", classes}};
}
} // namespace

void check_report(const nlohmann::json &report, std::string_view benchmark,
                  const std::string &where) {
    const Checked c(report, where);
    if (benchmark == "stream") {
        c.positive("/best_triad_GBps");
        if (report.contains("best_triad_nt_GBps"))
            c.non_negative("/best_triad_nt_GBps");
        for (std::size_t i = 0, n = c.array("/results"); i < n; ++i) {
            const auto r = at_index("/results", i);
            c.integer(r + "/threads", 1, 1 << 20);
            c.string(r + "/affinity");
            c.positive(r + "/kernels/triad/best_GBps");
        }
    } else if (benchmark == "dgemm" || benchmark == "dgemm-alternative") {
        if (benchmark == "dgemm") {
            c.positive("/peak_probe/all_cores_gflops");
            c.positive("/peak_probe/per_core_gflops");
        }
        c.positive("/best_gflops");
        for (std::size_t i = 0, n = c.array("/results"); i < n; ++i) {
            const auto r = at_index("/results", i);
            c.integer(r + "/threads", 1, 1 << 20);
            c.positive(r + "/gflops");
        }
    } else if (benchmark == "pingpong") {
        const auto ranks = c.integer("/ranks", 2, 1 << 20);
        for (const char *m : {"/alpha_matrix_s", "/beta_matrix_s_per_byte"}) {
            if (c.array(m) != static_cast<std::size_t>(ranks))
                c.fail(m, "has " +
                              std::to_string(report.at(nlohmann::json::json_pointer(m)).size()) +
                              " rows, expected /ranks = " + std::to_string(ranks));
            for (long long i = 0; i < ranks; ++i) {
                const auto row = at_index(m, static_cast<std::size_t>(i));
                if (c.array(row) != static_cast<std::size_t>(ranks))
                    c.fail(row, "has the wrong length, expected /ranks = " + std::to_string(ranks));
                for (long long k = 0; k < ranks; ++k)
                    if (i != k)
                        c.non_negative(at_index(row, static_cast<std::size_t>(k)));
            }
        }
        c.object("/classes");
        for (std::size_t i = 0, n = c.array("/pairs"); i < n; ++i) {
            const auto pr = at_index("/pairs", i);
            if (c.array(pr + "/ranks") != 2)
                c.fail(pr + "/ranks", "does not hold two ranks");
            c.integer(pr + "/ranks/0", 0, ranks - 1);
            c.integer(pr + "/ranks/1", 0, ranks - 1);
            c.string(pr + "/locality");
            for (std::size_t k = 0, m = c.array(pr + "/pieces"); k < m; ++k) {
                const auto pc = at_index(pr + "/pieces", k);
                c.finite(pc + "/alpha_s"); // a fitted intercept may dip below 0
                c.non_negative(pc + "/beta_s_per_byte");
                c.positive(pc + "/first_bytes");
                c.positive(pc + "/last_bytes");
            }
        }
    } else if (benchmark == "exchange") {
        c.integer("/ranks", 2, 1 << 20);
        c.integer("/cores", 1, 1 << 20);
        if (!c.at("/oversubscribed").is_boolean())
            c.fail("/oversubscribed", "is not true or false");
        for (std::size_t i = 0, n = c.array("/points"); i < n; ++i) {
            const auto pt = at_index("/points", i);
            c.non_negative(pt + "/gap_s_mean");
            c.positive(pt + "/payload_bytes");
            c.non_negative(pt + "/shift/mean_s");
        }
    } else {
        throw std::invalid_argument("check_report: unknown benchmark kind");
    }
}

nlohmann::json build_profile(nlohmann::json header, const nlohmann::json &stream,
                             const nlohmann::json &dgemm, const nlohmann::json &pingpong,
                             const std::vector<nlohmann::json> &dgemm_alternatives,
                             const std::vector<nlohmann::json> &exchanges) {
    using ptr = nlohmann::json::json_pointer;
    nlohmann::json p = std::move(header);
    const double peak = require_number(dgemm, ptr("/peak_probe/all_cores_gflops"), "dgemm");
    const double per_core = require_number(dgemm, ptr("/peak_probe/per_core_gflops"), "dgemm");
    const double triad = require_number(stream, ptr("/best_triad_GBps"), "stream");
    p["peak_gflops"] = peak;
    p["peak_gflops_per_core"] = per_core;
    p["dgemm_gflops"] = require_number(dgemm, ptr("/best_gflops"), "dgemm");
    p["dgemm_fraction_of_peak"] = p["dgemm_gflops"].get<double>() / peak;
    p["dgemm_corename"] = dgemm.value("corename", "unknown");
    p["stream_triad_GBps"] = triad;
    p["stream_triad_nt_GBps"] = stream.value("best_triad_nt_GBps", 0.0);
    // Roofline ridge: below this operational intensity a kernel is bandwidth bound.
    p["ridge_flop_per_byte"] = peak / triad;

    for (const auto &r : stream.at("results"))
        p["stream_triad_by_threads"].push_back(
            {{"threads", r.at("threads")},
             {"affinity", r.at("affinity")},
             {"vector_bits", r.value("vector_bits", 0)},
             {"best_GBps", r.at("/kernels/triad/best_GBps"_json_pointer)}});

    p["dgemm_coretypes"].push_back(coretype_entry(dgemm));
    for (const auto &alt : dgemm_alternatives) {
        auto e = coretype_entry(alt);
        // The alternative runs skip the probe: rate them against this profile's ceiling.
        for (auto &r : e["results"]) {
            const int t = r.value("threads", 1);
            r["fraction_of_peak"] = r.value("gflops", 0.0) / std::min(per_core * t, peak);
        }
        p["dgemm_coretypes"].push_back(std::move(e));
    }
    if (dgemm.contains("coretype_advice"))
        p["dgemm_coretype_advice"] = dgemm["coretype_advice"];

    p["alpha_matrix_s"] = pingpong.at("alpha_matrix_s");
    p["beta_matrix_s_per_byte"] = pingpong.at("beta_matrix_s_per_byte");
    p["comm_classes"] = pingpong.value("classes", nlohmann::json::object());
    p["hockney"] = hockney_section(pingpong);
    if (!exchanges.empty()) {
        p["exchange"] = nlohmann::json::array();
        for (const auto &e : exchanges)
            p["exchange"].push_back({{"ranks", e.at("ranks")},
                                     {"cores", e.at("cores")},
                                     {"oversubscribed", e.at("oversubscribed")},
                                     {"timestamp", e.value("timestamp", "")},
                                     {"config", e.value("config", nlohmann::json())},
                                     {"points", e.at("points")}});
        ExchangeModel::from_profile(p); // refuses a malformed report here, not in a later run
    }
    p["timestamps"] = {{"stream", stream.value("timestamp", "")},
                       {"dgemm", dgemm.value("timestamp", "")},
                       {"pingpong", pingpong.value("timestamp", "")},
                       {"profile", p.value("timestamp", "")}};
    p["stream"] = stream;
    p["dgemm"] = dgemm;
    p["dgemm_alternatives"] = dgemm_alternatives;
    p["pingpong"] = pingpong;
    return p;
}

void add_inter_node(nlohmann::json &profile, const nlohmann::json &pingpong_nodes,
                    const std::string &where) {
    const nlohmann::json h = hockney_section(pingpong_nodes);
    if (!h["classes"].contains("other_node"))
        throw UsageError(where + " has no pair of ranks on different nodes (run it with one "
                                 "rank per node on two or more nodes: "
                                 "scripts/slurm/pingpong-nodes.sbatch)");
    auto &pairs = profile["hockney"]["pairs"];
    // A second merge replaces the first: the newest inter-node measurement wins.
    nlohmann::json kept = nlohmann::json::array();
    for (auto &p : pairs)
        if (p.value("locality", "") != "other_node")
            kept.push_back(std::move(p));
    for (const auto &p : h["pairs"])
        if (p.value("locality", "") == "other_node")
            kept.push_back(p);
    pairs = std::move(kept);
    profile["hockney"]["classes"]["other_node"] = h["classes"]["other_node"];
    const auto &summary = pingpong_nodes.value("classes", nlohmann::json::object());
    if (summary.contains("other_node"))
        profile["comm_classes"]["other_node"] = summary["other_node"];
    profile["timestamps"]["pingpong_nodes"] = pingpong_nodes.value("timestamp", "");
    profile["pingpong_nodes"] = pingpong_nodes;
}

} // namespace sphperf::model
