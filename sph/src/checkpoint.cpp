#include "sphperf/sph/checkpoint.hpp"

#include "sphperf/sph/balance.hpp"

#include "sphperf/build_info.hpp"
#include "sphperf/errors.hpp"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <type_traits>

namespace sphperf::sph {

namespace {
constexpr char rank_magic[8] = {'S', 'P', 'H', 'C', 'K', 'R', 'K', '1'};
// 2: the rank records split comm by exchange (RankInterval::fields changed); 3: they carry the
// CPU time before each shift and the exchange benchmark's prediction apart; 4: the speed
// gauge's samples; 6: the core latency gauge's.
constexpr char record_magic[8] = {'S', 'P', 'H', 'C', 'K', 'R', 'C', '6'};

// Native-endian binary writer: the files are read back by the same build on the same machine
// (the manifest's commit is checked), so no portable encoding is needed.
class Out {
public:
    template <class T> void put(const T &v) {
        static_assert(std::is_trivially_copyable_v<T>);
        buf_.append(reinterpret_cast<const char *>(&v), sizeof v);
    }
    template <class T> void put(const std::vector<T> &v) {
        static_assert(std::is_trivially_copyable_v<T>);
        put<std::uint64_t>(v.size());
        if (!v.empty()) // an empty vector's data() may be null
            buf_.append(reinterpret_cast<const char *>(v.data()), v.size() * sizeof(T));
    }
    void magic(const char (&m)[8]) { buf_.append(m, 8); }
    std::string take() { return std::move(buf_); }

private:
    std::string buf_;
};

class In {
public:
    In(const std::string &bytes, std::string where) : b_(bytes), where_(std::move(where)) {}
    template <class T> T get() {
        static_assert(std::is_trivially_copyable_v<T>);
        need(sizeof(T));
        T v;
        std::memcpy(&v, b_.data() + pos_, sizeof v);
        pos_ += sizeof v;
        return v;
    }
    template <class T> std::vector<T> vec() {
        const auto n = get<std::uint64_t>();
        if (n > (b_.size() - pos_) / sizeof(T))
            throw UsageError(where_ + ": truncated (an array of " + std::to_string(n) +
                             " elements runs past the end of the file)");
        std::vector<T> v(n);
        if (n > 0) // memcpy from or to null is undefined even for 0 bytes (UBSan)
            std::memcpy(v.data(), b_.data() + pos_, n * sizeof(T));
        pos_ += n * sizeof(T);
        return v;
    }
    void magic(const char (&m)[8], const char *what) {
        need(8);
        if (std::memcmp(b_.data(), m, 8) != 0)
            throw UsageError(where_ + ": not a " + what + " (wrong magic bytes)");
        pos_ += 8;
    }
    void end() const {
        if (pos_ != b_.size())
            throw UsageError(where_ + ": " + std::to_string(b_.size() - pos_) +
                             " unexpected bytes after the data");
    }

private:
    void need(std::size_t n) const {
        if (b_.size() - pos_ < n)
            throw UsageError(where_ + ": truncated at byte " + std::to_string(pos_));
    }
    const std::string &b_;
    std::string where_;
    std::size_t pos_ = 0;
};
} // namespace

RankState RankState::of(const Particles &p) {
    RankState s;
    s.owned = p.owned();
    s.fluid = p.fluid();
    s.x = p.x;
    s.y = p.y;
    s.vx = p.vx;
    s.vy = p.vy;
    s.rho = p.rho;
    s.p = p.p;
    s.mass = p.mass;
    s.ax = p.ax;
    s.ay = p.ay;
    s.id = p.id;
    s.kind.reserve(p.kind.size());
    for (Kind k : p.kind)
        s.kind.push_back(static_cast<std::uint8_t>(k));
    return s;
}

void RankState::restore(Particles &p) const {
    p = Particles{};
    const std::size_t n = x.size();
    for (std::size_t i = 0; i < n; ++i) {
        const ParticleRecord r{x[i],    y[i],   vx[i],
                               vy[i],   rho[i], this->p[i],
                               mass[i], id[i],  static_cast<Kind>(kind[i])};
        if (i < owned)
            p.add_owned(r);
        else
            p.add_transient(r);
        p.ax[i] = ax[i];
        p.ay[i] = ay[i];
    }
    if (p.owned() != owned || p.fluid() != fluid)
        throw std::runtime_error("checkpoint of rank " + std::to_string(rank) +
                                 ": particles out of order (fluid, walls, transient)");
}

void RankState::append_owned(std::vector<ParticleRecord> &out, std::vector<double> &ax_out,
                             std::vector<double> &ay_out) const {
    for (std::size_t i = 0; i < owned; ++i) {
        out.push_back(
            {x[i], y[i], vx[i], vy[i], rho[i], p[i], mass[i], id[i], static_cast<Kind>(kind[i])});
        ax_out.push_back(ax[i]);
        ay_out.push_back(ay[i]);
    }
}

std::uint64_t fnv1a64(const std::string &bytes) {
    std::uint64_t h = 0xcbf29ce484222325ULL;
    for (unsigned char c : bytes) {
        h ^= c;
        h *= 0x100000001b3ULL;
    }
    return h;
}

std::string hex64(std::uint64_t v) {
    char s[17];
    std::snprintf(s, sizeof s, "%016llx", static_cast<unsigned long long>(v));
    return s;
}

std::string serialise(const RankState &s) {
    Out o;
    o.magic(rank_magic);
    o.put(s.step);
    o.put(s.rank);
    o.put(s.ranks);
    o.put(s.owned);
    o.put(s.fluid);
    for (const auto *v : {&s.x, &s.y, &s.vx, &s.vy, &s.rho, &s.p, &s.mass, &s.ax, &s.ay})
        o.put(*v);
    o.put(s.id);
    o.put(s.kind);
    o.put(s.grid_state);
    o.put(s.idle_s);
    o.put(s.interactions_total);
    o.put(s.timers);
    return o.take();
}

RankState deserialise_rank(const std::string &bytes, const std::string &where) {
    In in(bytes, where);
    in.magic(rank_magic, "rank checkpoint file");
    RankState s;
    s.step = in.get<std::int64_t>();
    s.rank = in.get<int>();
    s.ranks = in.get<int>();
    s.owned = in.get<std::uint64_t>();
    s.fluid = in.get<std::uint64_t>();
    for (auto *v : {&s.x, &s.y, &s.vx, &s.vy, &s.rho, &s.p, &s.mass, &s.ax, &s.ay})
        *v = in.vec<double>();
    s.id = in.vec<std::int64_t>();
    s.kind = in.vec<std::uint8_t>();
    s.grid_state = in.vec<std::int64_t>();
    s.idle_s = in.get<double>();
    s.interactions_total = in.get<double>();
    s.timers = in.vec<double>();
    in.end();
    const std::size_t n = s.x.size();
    for (const auto *v : {&s.y, &s.vx, &s.vy, &s.rho, &s.p, &s.mass, &s.ax, &s.ay})
        if (v->size() != n)
            throw UsageError(where + ": particle arrays of different lengths");
    if (s.id.size() != n || s.kind.size() != n || s.owned > n || s.fluid > s.owned)
        throw UsageError(where + ": particle counts do not fit the arrays");
    for (auto k : s.kind)
        if (k > static_cast<std::uint8_t>(Kind::mirror))
            throw UsageError(where + ": unknown particle kind " + std::to_string(k));
    return s;
}

std::string serialise(const RecordSoFar &r) {
    Out o;
    o.magic(record_magic);
    o.put(r.fluid_particles);
    o.put(r.wall_particles);
    o.put(r.initial_columns);
    o.put<std::uint64_t>(r.intervals.size());
    for (const auto &iv : r.intervals) {
        o.put(iv.step);
        o.put(iv.time_s);
        o.put(iv.columns);
        o.put(iv.column_interactions);
        o.put(iv.column_descents);
        std::vector<double> packed;
        for (const auto &rk : iv.ranks) {
            const auto a = rk.pack();
            packed.insert(packed.end(), a.begin(), a.end());
        }
        o.put(packed);
    }
    for (const auto *v :
         {&r.physics.time_s, &r.physics.front_x, &r.physics.mass, &r.physics.kinetic_energy})
        o.put(*v);
    return o.take();
}

RecordSoFar deserialise_record(const std::string &bytes, const std::string &where) {
    In in(bytes, where);
    in.magic(record_magic, "run record checkpoint file");
    RecordSoFar r;
    r.fluid_particles = in.get<std::int64_t>();
    r.wall_particles = in.get<std::int64_t>();
    r.initial_columns = in.vec<double>();
    const auto n = in.get<std::uint64_t>();
    if (n > bytes.size())
        throw UsageError(where + ": " + std::to_string(n) + " intervals cannot fit in the file");
    for (std::uint64_t k = 0; k < n; ++k) {
        IntervalRecord iv;
        iv.step = in.get<std::int64_t>();
        iv.time_s = in.get<double>();
        iv.columns = in.vec<double>();
        iv.column_interactions = in.vec<double>();
        iv.column_descents = in.vec<double>();
        const auto packed = in.vec<double>();
        if (packed.size() % RankInterval::fields != 0)
            throw UsageError(where + ": interval " + std::to_string(k) +
                             " holds a partial rank record");
        for (std::size_t i = 0; i < packed.size(); i += RankInterval::fields)
            iv.ranks.push_back(RankInterval::unpack(&packed[i]));
        r.intervals.push_back(std::move(iv));
    }
    for (auto *v :
         {&r.physics.time_s, &r.physics.front_x, &r.physics.mass, &r.physics.kinetic_energy})
        *v = in.vec<double>();
    in.end();
    return r;
}

void write_atomically(const std::filesystem::path &path, const std::string &bytes) {
    const std::filesystem::path tmp = path.string() + ".tmp";
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        out.flush();
        if (!out)
            throw std::runtime_error("cannot write checkpoint file '" + tmp.string() + "'");
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec)
        throw std::runtime_error("cannot rename '" + tmp.string() + "' to '" + path.string() +
                                 "': " + ec.message());
}

std::string read_file(const std::filesystem::path &path) {
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw UsageError("cannot read checkpoint file '" + path.string() + "'");
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string step_dir_name(std::int64_t step) {
    char s[32];
    std::snprintf(s, sizeof s, "step_%09lld", static_cast<long long>(step));
    return s;
}

std::filesystem::path manifest_path(const std::filesystem::path &dir) {
    return dir / "manifest.json";
}

// Flat records: nlohmann's own (de)serialisers, key = member name; a missing key throws.
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(CheckpointFile, name, bytes, fnv1a64)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(RebalanceRecord, step, cuts, moved, seconds, imbalance_before,
                                   imbalance_after)
void to_json(nlohmann::json &j, const Manifest &m) {
    j = {{"schema", m.schema},
         {"kind", "sph-checkpoint"},
         {"git_commit", m.git_commit},
         {"step", m.step},
         {"ranks", m.ranks},
         {"config",
          {{"setup", m.setup},
           {"grid", m.grid},
           {"boundary", m.boundary},
           {"scale", m.scale},
           {"delta", m.delta},
           {"dt", m.dt},
           {"alpha", m.alpha},
           {"column_width", m.column_width},
           {"shepard_every", m.shepard_every},
           {"interval", m.interval}}},
         {"files", m.files},
         {"cuts", m.cuts},
         {"rebalances", m.rebalances}};
}
void from_json(const nlohmann::json &j, Manifest &m) {
    j.at("schema").get_to(m.schema);
    j.at("git_commit").get_to(m.git_commit);
    j.at("step").get_to(m.step);
    j.at("ranks").get_to(m.ranks);
    const auto &c = j.at("config");
    c.at("setup").get_to(m.setup);
    c.at("grid").get_to(m.grid);
    c.at("boundary").get_to(m.boundary);
    c.at("scale").get_to(m.scale);
    c.at("delta").get_to(m.delta);
    c.at("dt").get_to(m.dt);
    c.at("alpha").get_to(m.alpha);
    c.at("column_width").get_to(m.column_width);
    c.at("shepard_every").get_to(m.shepard_every);
    c.at("interval").get_to(m.interval);
    j.at("files").get_to(m.files);
    if (j.contains("cuts"))
        j.at("cuts").get_to(m.cuts);
    if (j.contains("rebalances"))
        j.at("rebalances").get_to(m.rebalances);
}

Manifest read_manifest(const std::filesystem::path &dir) {
    const auto path = manifest_path(dir);
    if (!std::filesystem::exists(path))
        throw UsageError("no checkpoint in '" + dir.string() + "': " + path.string() +
                         " does not exist");
    try {
        const auto j = nlohmann::json::parse(read_file(path));
        Manifest m = j.get<Manifest>();
        if (m.step < 0 || m.ranks < 1 || m.files.size() != static_cast<std::size_t>(m.ranks) + 1)
            throw UsageError(path.string() + ": step " + std::to_string(m.step) + ", " +
                             std::to_string(m.ranks) + " ranks and " +
                             std::to_string(m.files.size()) +
                             " files do not fit (expected step >= 0 and one file per rank plus "
                             "the record)");
        if (!m.cuts.empty()) {
            try {
                check_cuts(m.cuts, m.ranks, m.cuts.back());
            } catch (const std::invalid_argument &e) {
                throw UsageError(path.string() + ": " + e.what());
            }
        }
        return m;
    } catch (const nlohmann::json::exception &e) {
        throw UsageError(path.string() + ": not a checkpoint manifest (" + e.what() + ")");
    }
}

void write_manifest(const std::filesystem::path &dir, const Manifest &m) {
    write_atomically(manifest_path(dir), nlohmann::json(m).dump(2) + "\n");
}

Manifest manifest_for(const Config &cfg, std::int64_t step, int ranks) {
    Manifest m;
    m.schema = checkpoint_schema;
    m.git_commit = std::string(build::git_commit());
    m.step = step;
    m.ranks = ranks;
    m.setup = std::string(to_string(cfg.setup));
    m.grid = std::string(to_string(cfg.grid));
    m.boundary = std::string(to_string(cfg.boundary));
    m.scale = cfg.scale;
    m.delta = cfg.physics.delta;
    m.dt = cfg.dt;
    m.alpha = cfg.physics.alpha;
    m.column_width = cfg.column_width;
    m.shepard_every = cfg.physics.shepard_every;
    m.interval = cfg.interval;
    return m;
}

Manifest verify_checkpoint(const std::filesystem::path &dir, const Config &cfg) {
    const Manifest m = read_manifest(dir);
    const std::string where = manifest_path(dir).string();
    if (m.schema != checkpoint_schema)
        throw UsageError(where + ": schema " + std::to_string(m.schema) + ", this sph reads " +
                         std::to_string(checkpoint_schema));
    if (m.git_commit != build::git_commit())
        throw UsageError(where + ": written by sph at commit " + m.git_commit +
                         ", this sph is commit " + std::string(build::git_commit()) +
                         " (a restart needs the same code)");
    const Manifest want = manifest_for(cfg, m.step, m.ranks);
    auto text = [](double v) {
        std::ostringstream s;
        s << v;
        return s.str();
    };
    auto same = [&](const char *key, const std::string &have, const std::string &given) {
        if (have != given)
            throw UsageError(where + ": " + key + " " + have + " in the checkpoint, " + given +
                             " in this run");
    };
    same("setup", m.setup, want.setup);
    same("grid", m.grid, want.grid);
    same("boundary", m.boundary, want.boundary);
    // Exact: a restart continues the same floating-point trajectory.
    for (auto [key, have, given] : {std::tuple{"scale", m.scale, want.scale},
                                    {"delta", m.delta, want.delta},
                                    {"dt", m.dt, want.dt},
                                    {"alpha", m.alpha, want.alpha},
                                    {"column-width", m.column_width, want.column_width}})
        if (have != given)
            throw UsageError(where + ": " + key + " " + text(have) + " in the checkpoint, " +
                             text(given) + " in this run");
    same("shepard-every", std::to_string(m.shepard_every), std::to_string(want.shepard_every));
    same("interval", std::to_string(m.interval), std::to_string(want.interval));
    if (!m.cuts.empty() && m.cuts.back() != make_geometry(cfg).cell_columns)
        throw UsageError(where + ": slab cuts end at column " + std::to_string(m.cuts.back()) +
                         ", this run's tank has " +
                         std::to_string(make_geometry(cfg).cell_columns) + " columns");
    if (cfg.total_steps() <= m.step)
        throw UsageError(where + ": the checkpoint is at step " + std::to_string(m.step) +
                         ", this run ends at step " + std::to_string(cfg.total_steps()) +
                         " (expected a later end)");
    for (const auto &f : m.files) {
        const auto path = dir / f.name;
        if (f.name.find("..") != std::string::npos || !std::filesystem::exists(path))
            throw UsageError(where + " names " + f.name + ", which does not exist");
        const std::string bytes = read_file(path);
        if (bytes.size() != f.bytes)
            throw UsageError(path.string() + ": " + std::to_string(bytes.size()) +
                             " bytes, the manifest says " + std::to_string(f.bytes) +
                             " (truncated or replaced)");
        if (hex64(fnv1a64(bytes)) != f.fnv1a64)
            throw UsageError(path.string() + ": checksum " + hex64(fnv1a64(bytes)) +
                             ", the manifest says " + f.fnv1a64 + " (corrupt)");
    }
    return m;
}

} // namespace sphperf::sph
