#include "sphperf/errors.hpp"
#include "sphperf/model/profile.hpp"
#include "sphperf/report.hpp"
#include "sphperf/topology.hpp"

#include <gtest/gtest.h>

#include <cstdlib>

using nlohmann::json;

namespace {
json stream_report() {
    return {{"benchmark", "stream"},
            {"best_triad_GBps", 40.0},
            {"best_triad_nt_GBps", 50.0},
            {"results",
             {{{"threads", 1},
               {"affinity", "compact"},
               {"kernels", {{"triad", {{"best_GBps", 30.0}}}}}},
              {{"threads", 2},
               {"affinity", "compact"},
               {"kernels", {{"triad", {{"best_GBps", 40.0}}}}}}}}};
}
json dgemm_report() {
    return {
        {"benchmark", "dgemm"},
        {"corename", "Haswell"},
        {"best_gflops", 60.0},
        {"peak_probe", {{"per_core_gflops", 50.0}, {"all_cores_gflops", 100.0}}},
        {"results", {{{"n", 1000}, {"threads", 2}, {"gflops", 60.0}, {"fraction_of_peak", 0.6}}}}};
}
json pingpong_report() {
    return {{"benchmark", "pingpong"},
            {"alpha_matrix_s", {{nullptr, 1e-6}, {1e-6, nullptr}}},
            {"beta_matrix_s_per_byte", {{nullptr, 1e-10}, {1e-10, nullptr}}},
            {"classes", {{"same_l3", {{"pairs", 1}}}}}};
}
} // namespace

TEST(Profile, DerivesHeadlineFiguresAndKeepsTheReports) {
    json alt = dgemm_report();
    alt.erase("peak_probe");
    alt["corename"] = "SkylakeX";
    alt["best_gflops"] = 90.0;
    alt["results"][0]["gflops"] = 90.0;
    const json p = sphperf::model::build_profile({{"schema", 1}}, stream_report(), dgemm_report(),
                                                 pingpong_report(), {alt});
    EXPECT_DOUBLE_EQ(p["peak_gflops"].get<double>(), 100.0);
    EXPECT_DOUBLE_EQ(p["dgemm_gflops"].get<double>(), 60.0);
    EXPECT_DOUBLE_EQ(p["stream_triad_GBps"].get<double>(), 40.0);
    EXPECT_DOUBLE_EQ(p["ridge_flop_per_byte"].get<double>(), 2.5);
    EXPECT_DOUBLE_EQ(p["dgemm_fraction_of_peak"].get<double>(), 0.6);
    ASSERT_EQ(p["dgemm_coretypes"].size(), 2u);
    EXPECT_DOUBLE_EQ(p["dgemm_coretypes"][1]["results"][0]["fraction_of_peak"].get<double>(), 0.9);
    EXPECT_EQ(p["stream_triad_by_threads"].size(), 2u);
    for (const char *key : {"stream", "dgemm", "pingpong", "alpha_matrix_s",
                            "beta_matrix_s_per_byte", "comm_classes", "timestamps", "schema"})
        EXPECT_TRUE(p.contains(key)) << key;
}

TEST(Profile, MissingFigureIsAUsageError) {
    json d = dgemm_report();
    d.erase("peak_probe");
    EXPECT_THROW(sphperf::model::build_profile({}, stream_report(), d, pingpong_report(), {}),
                 sphperf::UsageError);
}

namespace {
nlohmann::json pair_of(const char *locality, double alpha) {
    return {{"ranks", {0, 1}},
            {"locality", locality},
            {"breakpoint_bytes", 0},
            {"pieces",
             {{{"alpha_s", alpha},
               {"beta_s_per_byte", 1e-10},
               {"first_bytes", 1},
               {"last_bytes", 1 << 20}}}}};
}
} // namespace

// The inter-node ping-pong adds its class and pairs (without processing units, which mean
// nothing across nodes); a second merge replaces the first; a report of one node is refused.
TEST(Profile, InterNodeReportAddsItsClass) {
    json intra = pingpong_report();
    intra["pairs"] = {pair_of("same_l3", 1e-7)};
    intra["rank_placement"] = {{{"rank", 0}, {"last_cpu", 0}, {"bound_to_one_core", true}},
                               {{"rank", 1}, {"last_cpu", 1}, {"bound_to_one_core", true}}};
    json p = sphperf::model::build_profile({}, stream_report(), dgemm_report(), intra, {});
    json nodes = intra;
    nodes["pairs"] = {pair_of("other_node", 5e-6)};
    nodes["classes"] = {{"other_node", {{"pairs", 1}}}};
    sphperf::model::add_inter_node(p, nodes, "nodes.json");
    sphperf::model::add_inter_node(p, nodes, "nodes.json");
    EXPECT_TRUE(p["hockney"]["classes"].contains("same_l3"));
    ASSERT_TRUE(p["hockney"]["classes"].contains("other_node"));
    EXPECT_DOUBLE_EQ(p["hockney"]["classes"]["other_node"]["pieces"][0]["alpha_s"].get<double>(),
                     5e-6);
    ASSERT_EQ(p["hockney"]["pairs"].size(), 2u);
    EXPECT_EQ(p["hockney"]["pairs"][0]["pus"], (json{0, 1}));
    EXPECT_FALSE(p["hockney"]["pairs"][1].contains("pus"));
    EXPECT_TRUE(p["comm_classes"].contains("other_node"));
    EXPECT_TRUE(p.contains("pingpong_nodes"));
    try {
        sphperf::model::add_inter_node(p, intra, "one-node.json");
        ADD_FAILURE() << "a one-node report was merged";
    } catch (const sphperf::UsageError &e) {
        EXPECT_NE(std::string(e.what()).find("one-node.json has no pair of ranks on different "
                                             "nodes"),
                  std::string::npos)
            << e.what();
    }
}

// Every report names the Open MPI transport settings its communication figures ran under, and
// not mpirun's launch bookkeeping.
TEST(ReportHeader, RecordsTheMpiTransportSettingsOnly) {
    ASSERT_EQ(setenv("OMPI_MCA_btl_vader_eager_limit", "12345", 1), 0);
    ASSERT_EQ(setenv("OMPI_MCA_orte_launch", "1", 1), 0);
    const char *pml = std::getenv("OMPI_MCA_pml");
    const std::string own_pml = pml ? pml : "";
    ASSERT_EQ(setenv("OMPI_MCA_pml", "ob1", 1), 0);
    sphperf::Topology topo;
    const json h = sphperf::report_header("test", topo);
    unsetenv("OMPI_MCA_btl_vader_eager_limit");
    unsetenv("OMPI_MCA_orte_launch");
    if (own_pml.empty())
        unsetenv("OMPI_MCA_pml");
    else
        setenv("OMPI_MCA_pml", own_pml.c_str(), 1);
    ASSERT_TRUE(h.contains("mpi_mca"));
    EXPECT_EQ(h.at("mpi_mca").value("btl_vader_eager_limit", ""), "12345");
    EXPECT_EQ(h.at("mpi_mca").value("pml", ""), "ob1"); // a selection, not a parameter
    EXPECT_FALSE(h.at("mpi_mca").contains("orte_launch"));
}
