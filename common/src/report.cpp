#include "sphperf/report.hpp"

#include "sphperf/build_info.hpp"
#include "sphperf/errors.hpp"
#include "sphperf/topology.hpp"

#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <fstream>
#include <system_error>

namespace sphperf {

std::string hostname() {
    std::array<char, 256> buf{};
    if (gethostname(buf.data(), buf.size() - 1) != 0)
        return "unknown";
    return buf.data();
}

std::string utc_timestamp() {
    const std::time_t now = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&now, &tm);
    std::array<char, 32> buf{};
    std::strftime(buf.data(), buf.size(), "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf.data();
}

namespace {
// Open MPI's transport and tuning parameters set in the environment (scripts/mpirun.sh sets the
// shared-memory eager limit, and the pml on a node without RDMA devices): every communication
// figure depends on them, the framework selections (btl, pml, coll) and their parameters
// alike. mpirun's own launch bookkeeping (orte_, ess_, session paths) is left out.
nlohmann::json mca_environment() {
    constexpr std::string_view prefix = "OMPI_MCA_";
    constexpr std::array<std::string_view, 4> kept{"btl", "pml", "coll", "mpi_"};
    nlohmann::json mca = nlohmann::json::object();
    for (char **e = environ; *e != nullptr; ++e) {
        const std::string_view entry(*e);
        const auto eq = entry.find('=');
        if (entry.substr(0, prefix.size()) != prefix || eq == std::string_view::npos)
            continue;
        const std::string_view name = entry.substr(prefix.size(), eq - prefix.size());
        for (const auto k : kept)
            if (name.substr(0, k.size()) == k)
                mca[std::string(name)] = std::string(entry.substr(eq + 1));
    }
    return mca;
}
} // namespace

nlohmann::json report_header(std::string_view benchmark, const Topology &topo) {
    return {{"schema", report_schema},
            {"benchmark", benchmark},
            {"git_commit", build::git_commit()},
            {"host", hostname()},
            {"timestamp", utc_timestamp()},
            {"build",
             {{"compiler", build::compiler()},
              {"flags", build::flags()},
              {"build_type", build::build_type()}}},
            {"topology", topo.summary()},
            {"mpi_mca", mca_environment()}};
}

namespace {
std::filesystem::path temp_path_for(const std::filesystem::path &path) {
    return path.string() + ".tmp." + std::to_string(getpid());
}
} // namespace

void JsonSink::check_writable(const std::filesystem::path &path) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::is_directory(path, ec))
        throw UsageError("output path '" + path.string() + "' is a directory, expected a file");
    const fs::path tmp = temp_path_for(path);
    std::ofstream probe(tmp);
    if (!probe)
        throw UsageError("cannot write output file '" + path.string() +
                         "': " + std::strerror(errno) + " (expected a writable location)");
    probe.close();
    fs::remove(tmp, ec);
}

JsonSink::JsonSink(std::optional<std::filesystem::path> path) : path_(std::move(path)) {
    if (path_)
        check_writable(*path_);
}

void JsonSink::write(const nlohmann::json &report) const {
    if (!path_)
        return;
    const auto tmp = temp_path_for(*path_);
    {
        std::ofstream out(tmp);
        out << report.dump(2) << '\n';
        if (!out)
            throw std::runtime_error("failed writing " + tmp.string());
    }
    std::filesystem::rename(tmp, *path_);
}

} // namespace sphperf
