#pragma once
// Every owned particle of a checkpoint (sph --checkpoint), by id: the full state of a run, for
// tests that compare runs particle by particle.
#include "sphperf/sph/checkpoint.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <map>

namespace sphperf::testing {

using State = std::map<std::int64_t, std::array<double, 5>>; // x, y, vx, vy, rho

inline State particles_of(const std::filesystem::path &dir) {
    namespace sph = sphperf::sph;
    const sph::Manifest m = sph::read_manifest(dir);
    State out;
    for (int r = 0; r < m.ranks; ++r) {
        const auto path = dir / m.files[static_cast<std::size_t>(r)].name;
        const sph::RankState s = sph::deserialise_rank(sph::read_file(path), path.string());
        for (std::size_t i = 0; i < s.owned; ++i)
            EXPECT_TRUE(
                out.emplace(s.id[i], std::array{s.x[i], s.y[i], s.vx[i], s.vy[i], s.rho[i]}).second)
                << "particle " << s.id[i] << " twice";
    }
    return out;
}

// How two states differ: particles not bitwise equal, and the largest position difference.
struct StateDiff {
    std::size_t differ = 0, missing = 0;
    double max_position = 0;
};
inline StateDiff diff(const State &a, const State &b) {
    StateDiff d;
    d.missing = a.size() > b.size() ? a.size() - b.size() : b.size() - a.size();
    for (const auto &[id, v] : a) {
        const auto it = b.find(id);
        if (it == b.end()) {
            ++d.missing;
            continue;
        }
        d.differ += v != it->second; // operator== on doubles: NaN fails, as it should
        d.max_position = std::max(
            {d.max_position, std::abs(v[0] - it->second[0]), std::abs(v[1] - it->second[1])});
    }
    return d;
}

// Bitwise: every particle's position, velocity and density.
inline void expect_same_particles(const std::filesystem::path &a, const std::filesystem::path &b) {
    const State pa = particles_of(a), pb = particles_of(b);
    ASSERT_GT(pa.size(), 0u);
    ASSERT_EQ(pa.size(), pb.size());
    const StateDiff d = diff(pa, pb);
    EXPECT_EQ(d.missing, 0u) << "particles missing";
    EXPECT_EQ(d.differ, 0u) << "particles whose position, velocity or density differ (largest "
                               "position difference "
                            << d.max_position << " m)";
}

} // namespace sphperf::testing
