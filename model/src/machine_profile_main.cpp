// machine-profile: merges the stream, dgemm and pingpong reports into machine.json.
#include "sphperf/cli.hpp"
#include "sphperf/model/comm_model.hpp"
#include "sphperf/model/profile.hpp"
#include "sphperf/report.hpp"
#include "sphperf/topology.hpp"

#include <cstdio>

namespace {

using namespace sphperf;

// 'path', built by appends: GCC 12 flags "'" + path.string() + "'" with a false -Wrestrict.
std::string quoted(const std::filesystem::path &path) {
    std::string s = "'";
    s.append(path.string()).append("'");
    return s;
}

struct Config {
    std::filesystem::path stream, dgemm, pingpong, pingpong_nodes, out;
    std::vector<std::filesystem::path> dgemm_alternatives, exchanges;
};

int run(int argc, char **argv) {
    Config cfg;
    cli::App app{"Merge the stream, dgemm and pingpong reports into one machine profile with "
                 "peak GFLOP/s, STREAM bandwidth, the roofline ridge point and the Hockney "
                 "parameters."};
    app.add_option("--stream", cfg.stream, "stream report (JSON)")->required();
    app.add_option("--dgemm", cfg.dgemm, "dgemm report (JSON) with the peak probe")->required();
    app.add_option("--dgemm-alt", cfg.dgemm_alternatives,
                   "dgemm reports run with other OpenBLAS core types");
    app.add_option("--pingpong", cfg.pingpong, "pingpong report (JSON)")->required();
    app.add_option(
        "--pingpong-nodes", cfg.pingpong_nodes,
        "pingpong report across two or more nodes (scripts/slurm/pingpong-nodes.sbatch): "
        "adds the other_node class");
    app.add_option("--exchange", cfg.exchanges,
                   "exchange reports (JSON), one per rank count, for the app's halo exchange");
    app.add_option("--out", cfg.out, "machine profile to write (JSON)")->required();
    parse_cli(app, argc, argv);

    const JsonSink sink(cfg.out);
    const Topology topo;
    // Loaded and checked in argument order, so the first bad file is the one named.
    auto checked = [](const std::filesystem::path &path, const char *benchmark, const char *kind) {
        auto j = model::load_report(path, benchmark);
        model::check_report(j, kind, quoted(path));
        return j;
    };
    const auto stream = checked(cfg.stream, "stream", "stream");
    const auto dgemm = checked(cfg.dgemm, "dgemm", "dgemm");
    const auto pingpong = checked(cfg.pingpong, "pingpong", "pingpong");
    std::vector<nlohmann::json> alts;
    for (const auto &a : cfg.dgemm_alternatives)
        alts.push_back(checked(a, "dgemm", "dgemm-alternative"));
    std::vector<nlohmann::json> exchanges;
    for (const auto &e : cfg.exchanges)
        exchanges.push_back(checked(e, "exchange", "exchange"));
    const auto nodes = cfg.pingpong_nodes.empty()
                           ? nlohmann::json()
                           : checked(cfg.pingpong_nodes, "pingpong", "pingpong");
    nlohmann::json profile;
    try {
        profile = model::build_profile(report_header("machine", topo), stream, dgemm, pingpong,
                                       alts, exchanges);
        if (!nodes.is_null())
            model::add_inter_node(profile, nodes, quoted(cfg.pingpong_nodes));
    } catch (const nlohmann::json::exception &e) {
        throw UsageError(std::string("a report lacks a field the profile needs: ") + e.what());
    }
    sink.write(profile);

    std::printf("machine profile of %s (%s, %d cores)\n",
                profile["host"].get<std::string>().c_str(),
                profile["topology"]["cpu_model"].get<std::string>().c_str(),
                profile["topology"]["cores"].get<int>());
    std::printf("  peak (FMA probe)   %8.1f GFLOP/s (%.1f per core)\n",
                profile["peak_gflops"].get<double>(),
                profile["peak_gflops_per_core"].get<double>());
    for (const auto &c : profile["dgemm_coretypes"])
        std::printf("  DGEMM %-12s %8.1f GFLOP/s\n", c["corename"].get<std::string>().c_str(),
                    c["best_gflops"].get<double>());
    std::printf("  STREAM triad       %8.1f GB/s (non-temporal %.1f)\n",
                profile["stream_triad_GBps"].get<double>(),
                profile["stream_triad_nt_GBps"].get<double>());
    std::printf("  ridge point        %8.2f flop/byte\n",
                profile["ridge_flop_per_byte"].get<double>());
    for (const auto &[name, c] : profile["comm_classes"].items())
        std::printf("  MPI %-14s alpha %.3f us, 1/beta %.2f GB/s (%d pairs, max avg)\n",
                    name.c_str(), c["alpha_s_max"].get<double>() * 1e6,
                    1e-9 / c["beta_s_per_byte_max"].get<double>(), c["pairs"].get<int>());
    const auto exchange = model::ExchangeModel::from_profile(profile);
    for (const auto &set : exchange.sets()) {
        std::printf("  halo exchange, %d ranks: 1 KiB shift after 1 / 10 ms of compute %.1f / "
                    "%.1f us (mean)",
                    set.ranks, model::ExchangeModel::shift_seconds(set, 1e-3, 1024) * 1e6,
                    model::ExchangeModel::shift_seconds(set, 1e-2, 1024) * 1e6);
        if (set.has(model::ShiftMode::following))
            std::printf(
                ", right after another shift %.1f / %.1f us",
                model::ExchangeModel::shift_seconds(set, 1e-3, 1024, model::ShiftMode::following) *
                    1e6,
                model::ExchangeModel::shift_seconds(set, 1e-2, 1024, model::ShiftMode::following) *
                    1e6);
        std::printf("\n");
    }
    std::printf("written %s\n", cfg.out.string().c_str());
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    return sphperf::guarded_main("machine-profile", [&] { return run(argc, argv); });
}
