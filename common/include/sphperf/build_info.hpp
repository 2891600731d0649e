#pragma once
// Provenance of this binary, written at build time by cmake/WriteBuildInfo.cmake.
#include <string_view>

namespace sphperf::build {
std::string_view git_commit();
std::string_view compiler();
std::string_view flags();
std::string_view build_type();
} // namespace sphperf::build
