#pragma once
// Checkpoint and restart. A checkpoint is a directory of step_<S>/ subdirectories, one binary
// file per rank plus the run's record so far (rank 0), and manifest.json naming the latest
// complete one with every file's size and checksum. Files are written under a temporary name
// and renamed; the manifest moves to a new step only once every rank's file is complete, and
// the previous step's files are deleted only after that, so a run killed at any moment leaves
// a valid checkpoint behind.
#include "sphperf/sph/config.hpp"
#include "sphperf/sph/particles.hpp"
#include "sphperf/sph/record.hpp"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace sphperf::sph {

constexpr int checkpoint_schema = 3; // 2: intervals carry overlap_s; 3: column descents

// What one rank saves after a step: all its particles (owned, then the transient ones of that
// step, so a restart at the same rank count resumes from exactly this memory state), the
// accelerations the next step's first half kick needs, its grid's own state, and its running
// totals.
struct RankState {
    std::int64_t step = 0;
    int rank = 0, ranks = 1;
    std::uint64_t owned = 0, fluid = 0;
    std::vector<double> x, y, vx, vy, rho, p, mass, ax, ay;
    std::vector<std::int64_t> id;
    std::vector<std::uint8_t> kind;
    std::vector<std::int64_t> grid_state;
    double idle_s = 0, interactions_total = 0;
    std::vector<double> timers; // total phase times, Phase order

    static RankState of(const Particles &p); // the particle arrays and counts
    void restore(Particles &p) const;        // every particle, as saved
    void append_owned(std::vector<ParticleRecord> &out, std::vector<double> &ax_out,
                      std::vector<double> &ay_out) const; // owned particles only
};

// The run so far, kept by rank 0: what the report needs from before the restart.
struct RecordSoFar {
    std::int64_t fluid_particles = 0, wall_particles = 0;
    std::vector<double> initial_columns;
    std::vector<IntervalRecord> intervals;
    PhysicsSeries physics;
};

struct CheckpointFile {
    std::string name; // relative to the checkpoint directory
    std::uint64_t bytes = 0;
    std::string fnv1a64; // 16 hex digits
};

// manifest.json, read into this struct (a missing key or a wrong type is exit 2, naming it).
struct Manifest {
    int schema = 0;
    std::string git_commit;
    std::int64_t step = 0;
    int ranks = 0;
    std::string setup, grid, boundary;
    double scale = 0, delta = 0, dt = 0, alpha = 0, column_width = 0;
    int shepard_every = 0, interval = 0;
    std::vector<CheckpointFile> files;       // rank_000.bin ... then record.bin
    std::vector<int> cuts;                   // the slabs the rank files hold (empty: equal)
    std::vector<RebalanceRecord> rebalances; // so far (balanced decomposition)
};

std::uint64_t fnv1a64(const std::string &bytes);
std::string hex64(std::uint64_t v);

// Serialised forms (the bytes written to a file), and back. Reading throws UsageError naming
// `where` on a wrong magic, a truncated or an over-long file.
std::string serialise(const RankState &s);
RankState deserialise_rank(const std::string &bytes, const std::string &where);
std::string serialise(const RecordSoFar &r);
RecordSoFar deserialise_record(const std::string &bytes, const std::string &where);

// Writes `bytes` to `path` through a temporary file and a rename (never a half-written file
// under the final name). Throws std::runtime_error naming the path.
void write_atomically(const std::filesystem::path &path, const std::string &bytes);
std::string read_file(const std::filesystem::path &path);

std::string step_dir_name(std::int64_t step);
std::filesystem::path manifest_path(const std::filesystem::path &dir);
Manifest read_manifest(const std::filesystem::path &dir);
void write_manifest(const std::filesystem::path &dir, const Manifest &m);
Manifest manifest_for(const Config &cfg, std::int64_t step, int ranks);

// The whole check before a restart, on one rank: the manifest exists and parses, it was written
// by this code version for this configuration (setup, grid, boundary, scale, spacing, dt,
// physics, interval), its step lies before the run's end, and every file it names has the
// recorded size and checksum. Throws UsageError with one line naming the file and the mismatch.
Manifest verify_checkpoint(const std::filesystem::path &dir, const Config &cfg);

} // namespace sphperf::sph
