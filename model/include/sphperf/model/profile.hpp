#pragma once
// The machine profile: the three benchmark reports merged into one document with the figures
// the performance model reads first (peak, bandwidth, ridge point, communication parameters).
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace sphperf::model {

// Reads a benchmark report and checks it is the expected kind; throws UsageError naming the file.
nlohmann::json load_report(const std::filesystem::path &path, std::string_view benchmark);

// Checks that a benchmark report of kind `benchmark` ("stream", "dgemm", "dgemm-alternative",
// "pingpong", "exchange") holds every figure the profile reads, each of the right type and
// range (finite, positive where a time or a rate; non-empty arrays; rank numbers in range).
// Throws UsageError with one line naming `where` (the file) and the JSON pointer of the key.
void check_report(const nlohmann::json &report, std::string_view benchmark,
                  const std::string &where);

// `header` is the envelope of the profile itself (schema, commit, host, topology).
// `dgemm_alternatives` are DGEMM reports run with another OpenBLAS core type (may be empty);
// `exchanges` are exchange reports, one per rank count (may be empty).
nlohmann::json build_profile(nlohmann::json header, const nlohmann::json &stream,
                             const nlohmann::json &dgemm, const nlohmann::json &pingpong,
                             const std::vector<nlohmann::json> &dgemm_alternatives,
                             const std::vector<nlohmann::json> &exchanges = {});

// Adds the inter-node class to a profile from a ping-pong report run with ranks on two or more
// nodes (scripts/slurm/pingpong-nodes.sbatch): its other_node pairs join hockney/pairs (without
// processing units: a PU number means nothing across nodes), its other_node class joins
// hockney/classes and comm_classes, and the report is kept as "pingpong_nodes". Throws
// UsageError naming `where` when the report has no pair of ranks on different nodes.
void add_inter_node(nlohmann::json &profile, const nlohmann::json &pingpong_nodes,
                    const std::string &where);

} // namespace sphperf::model
