#pragma once
// The contract every reader is fuzzed against: any bytes either parse or throw UsageError (the
// apps turn it into exit 2 with one line). Any other exception escapes the harness and libFuzzer
// reports it as a crash, as it does every AddressSanitizer or UBSan report.
#include "sphperf/errors.hpp"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

namespace sphperf::fuzz {

template <class F> void refuses_or_reads(F &&read) {
    try {
        read();
    } catch (const UsageError &) {
    }
}

// Readers that take a path get the bytes through one file per process.
inline std::filesystem::path scratch_file(const std::string &name, const std::uint8_t *data,
                                          std::size_t size) {
    static const auto dir = [] {
        const auto d =
            std::filesystem::temp_directory_path() / ("sphperf_fuzz_" + std::to_string(getpid()));
        std::filesystem::create_directories(d);
        return d;
    }();
    const auto path = dir / name;
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char *>(data), static_cast<std::streamsize>(size));
    return path;
}

} // namespace sphperf::fuzz
