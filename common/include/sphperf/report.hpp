#pragma once
// Common report envelope and safe JSON output. Every report carries `schema`, `benchmark`,
// `git_commit`, `host`, `topology`, `build` and a timestamp so results stay traceable.
#include <nlohmann/json.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace sphperf {

class Topology;

inline constexpr int report_schema = 1;

std::string hostname();
std::string utc_timestamp();

// The fields every report starts with.
nlohmann::json report_header(std::string_view benchmark, const Topology &topo);

// A JSON destination checked before any work starts (so a bad path fails fast, exit 2) and
// written atomically at the end (temporary file + rename: never a partial report).
class JsonSink {
public:
    JsonSink() = default;
    explicit JsonSink(std::optional<std::filesystem::path> path);

    bool enabled() const { return path_.has_value(); }
    const std::optional<std::filesystem::path> &path() const { return path_; }
    void write(const nlohmann::json &report) const;

    // Throws UsageError when `path` cannot be written.
    static void check_writable(const std::filesystem::path &path);

private:
    std::optional<std::filesystem::path> path_;
};

} // namespace sphperf
