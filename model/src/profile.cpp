#include "sphperf/model/profile.hpp"

#include "sphperf/cli.hpp"
#include "sphperf/model/comm_model.hpp"

#include <fstream>
#include <map>

namespace sphperf::model {

nlohmann::json load_report(const std::filesystem::path &path, std::string_view benchmark) {
    std::ifstream in(path);
    if (!in)
        throw UsageError("cannot read " + std::string(benchmark) + " report '" + path.string() +
                         "'");
    nlohmann::json j;
    try {
        in >> j;
    } catch (const nlohmann::json::exception &e) {
        throw UsageError("'" + path.string() + "' is not valid JSON (" + e.what() + ")");
    }
    if (!j.is_object() || j.value("benchmark", "") != benchmark)
        throw UsageError("'" + path.string() + "' is not a " + std::string(benchmark) +
                         " report (its \"benchmark\" field differs)");
    return j;
}

namespace {
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
        if (ranks.size() == 2 && pu_of_rank.count(ranks[0].get<int>()) &&
            pu_of_rank.count(ranks[1].get<int>()))
            e["pus"] = {pu_of_rank[ranks[0].get<int>()], pu_of_rank[ranks[1].get<int>()]};
        const PiecewiseFit fit = piecewise_from_json(e, "pingpong pair");
        const std::string loc = pr.value("locality", "unknown");
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

} // namespace sphperf::model
