#include "sphperf/sph/output.hpp"

#include "sphperf/report.hpp"
#include "sphperf/stats.hpp"
#include "sphperf/timer.hpp"

#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cstdio>
#include <fstream>
#include <numeric>
#include <set>

namespace sphperf::sph {

// RankInterval is doubles only, so it crosses ranks as an array of them (record.hpp checks the
// size): no field list to keep in step by hand.
std::array<double, RankInterval::fields> RankInterval::pack() const {
    return std::bit_cast<std::array<double, fields>>(*this);
}

RankInterval RankInterval::unpack(const double *v) {
    std::array<double, fields> a{};
    std::copy_n(v, fields, a.begin());
    return std::bit_cast<RankInterval>(a);
}

Progress::Progress(bool enabled, std::int64_t steps, double dt)
    : enabled_(enabled && isatty(STDERR_FILENO)), steps_(steps), dt_(dt), start_(wall_seconds()) {}

void Progress::update(std::int64_t step) {
    if (!enabled_)
        return;
    const double now = wall_seconds();
    constexpr double redraw_s = 0.5;
    if (now - last_ < redraw_s && step != steps_)
        return;
    last_ = now;
    const double rate = static_cast<double>(step) / std::max(now - start_, 1e-9);
    const double eta = static_cast<double>(steps_ - step) / std::max(rate, 1e-9);
    std::fprintf(stderr, "\rsph: step %lld/%lld  t=%.4f s  %.0f steps/s  ETA %.0f s   ",
                 static_cast<long long>(step), static_cast<long long>(steps_),
                 static_cast<double>(step) * dt_, rate, eta);
    drawn_ = true;
}

void Progress::finish() {
    if (drawn_)
        std::fprintf(stderr, "\n");
}

void write_vtu(const std::filesystem::path &path, const Particles &p, int rank) {
    std::ofstream out(path);
    const std::size_t n = p.owned();
    out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\">\n"
        << "<UnstructuredGrid><Piece NumberOfPoints=\"" << n << "\" NumberOfCells=\"" << n
        << "\">\n<Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < n; ++i)
        out << p.x[i] << ' ' << p.y[i] << " 0\n";
    out << "</DataArray></Points>\n<Cells>\n"
        << "<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < n; ++i)
        out << i << '\n';
    out << "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < n; ++i)
        out << i + 1 << '\n';
    out << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < n; ++i)
        out << "1\n"; // VTK_VERTEX
    out << "</DataArray>\n</Cells>\n<PointData Scalars=\"pressure\" Vectors=\"velocity\">\n"
        << "<DataArray type=\"Float64\" Name=\"velocity\" NumberOfComponents=\"3\" "
           "format=\"ascii\">\n";
    for (std::size_t i = 0; i < n; ++i)
        out << p.vx[i] << ' ' << p.vy[i] << " 0\n";
    out << "</DataArray>\n";
    auto scalar = [&](const char *field, auto &&value) {
        out << "<DataArray type=\"Float64\" Name=\"" << field << "\" format=\"ascii\">\n";
        for (std::size_t i = 0; i < n; ++i)
            out << value(i) << '\n';
        out << "</DataArray>\n";
    };
    scalar("density", [&](std::size_t i) { return p.rho[i]; });
    scalar("pressure", [&](std::size_t i) { return p.p[i]; });
    scalar("rank", [&](std::size_t) { return rank; });
    scalar("kind", [&](std::size_t i) { return static_cast<int>(p.kind[i]); });
    scalar("id", [&](std::size_t i) { return p.id[i]; });
    out << "</PointData>\n</Piece></UnstructuredGrid>\n</VTKFile>\n";
    if (!out)
        throw std::runtime_error("failed writing snapshot " + path.string());
}

void Snapshots::write(const std::filesystem::path &dir, std::int64_t index, double time,
                      const Particles &p, int rank, int ranks) {
    char name[64];
    std::snprintf(name, sizeof name, "sph_%06lld_r%03d.vtu", static_cast<long long>(index), rank);
    write_vtu(dir / name, p, rank);
    // Rank 0 indexes every rank's part: the names are predictable.
    if (rank == 0)
        for (int r = 0; r < ranks; ++r) {
            std::snprintf(name, sizeof name, "sph_%06lld_r%03d.vtu", static_cast<long long>(index),
                          r);
            entries_.push_back({time, r, name});
        }
}

void Snapshots::write_index(const std::filesystem::path &dir) const {
    std::ofstream out(dir / "sph.pvd");
    out << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n"
        << "<Collection>\n";
    for (const auto &e : entries_)
        out << "  <DataSet timestep=\"" << e.time << "\" part=\"" << e.part << "\" file=\""
            << e.file << "\"/>\n";
    out << "</Collection>\n</VTKFile>\n";
}

namespace {
nlohmann::json min_avg_max(const std::vector<double> &v) {
    const Summary s = summarize(v);
    return {{"min", s.min}, {"avg", s.avg}, {"max", s.max}};
}
} // namespace

nlohmann::json build_report(const RunRecord &run, const Topology &topo) {
    const Config &c = run.config;
    nlohmann::json j = report_header("sph", topo);
    j["config"] = {{"setup", to_string(c.setup)},
                   {"grid", to_string(c.grid)},
                   {"overlap", c.overlap},
                   {"halo_transport", to_string(c.halo_transport)},
                   {"reorder_every", c.reorder_every},
                   {"boundary", to_string(c.boundary)},
                   {"scale", c.scale},
                   {"delta", c.physics.delta},
                   {"dt", c.dt},
                   {"steps", run.steps},
                   {"ranks", run.ranks},
                   {"threads", run.threads},
                   {"interval", c.interval},
                   {"h", c.physics.h},
                   {"cell_size", run.geometry.cell_size},
                   {"cell_columns", run.geometry.cell_columns},
                   {"cell_rows", run.geometry.cell_rows},
                   {"tank_length", run.geometry.tank_length},
                   {"dam_width", run.geometry.dam_width},
                   {"dam_height", run.geometry.dam_height},
                   {"rho0", c.physics.rho0},
                   {"c0", c.physics.c0},
                   {"gamma", c.physics.gamma},
                   {"alpha", c.physics.alpha},
                   {"shepard_every", c.physics.shepard_every},
                   {"fluid_particles", run.geometry.fluid_particles()}};
    if (c.checkpoint_dir)
        j["config"]["checkpoint"] = {{"directory", c.checkpoint_dir->string()},
                                     {"every_steps", c.checkpoint_every}};
    if (run.restarted_from_step >= 0)
        j["restart"] = {{"from_step", run.restarted_from_step},
                        {"from", run.restarted_from.string()},
                        {"note", "intervals and physics before from_step come from the "
                                 "checkpoint; wall_s times the steps after it only"}};
    j["particles"] = {{"field", run.fluid_particles},
                      {"virtual", run.mean_virtual},
                      {"wall", run.wall_particles}};
    j["wall_s"] = run.wall_s;
    const double steps = static_cast<double>(run.steps);
    j["particle_steps_per_s"] =
        run.wall_s > 0 ? static_cast<double>(run.fluid_particles) * steps / run.wall_s : 0.0;
    j["neighbour_interactions_per_s"] = run.wall_s > 0 ? run.interactions_total / run.wall_s : 0.0;
    j["steps_per_s"] = run.wall_s > 0 ? steps / run.wall_s : 0.0;
    j["peak_rss_bytes"] = run.peak_rss_bytes;
    j["record_bytes"] = sizeof(ParticleRecord);
    j["placement_pus"] = run.placement_pus;
    j["placement_nodes"] = run.placement_nodes;
    j["nodes"] =
        std::set<std::string>(run.placement_nodes.begin(), run.placement_nodes.end()).size();
    j["machine"] = c.machine ? nlohmann::json(c.machine->string()) : nlohmann::json();
    j["exchange_report"] = c.exchange ? nlohmann::json(c.exchange->string()) : nlohmann::json();
    j["profile_probe_shift_s"] = run.profile_probe_shift_s;
    j["comm_predict_source"] = run.comm_predict_source.empty()
                                   ? nlohmann::json()
                                   : nlohmann::json(run.comm_predict_source);
    j["replay_slice_s"] = 1e-3 * c.replay_slice_ms;
    j["initial_columns"] = run.initial_columns;
    j["wall_columns"] = run.wall_columns;
    {
        nlohmann::json rebalances = nlohmann::json::array();
        for (const auto &r : run.rebalances)
            rebalances.push_back({{"step", r.step},
                                  {"cuts", r.cuts},
                                  {"moved_particles", r.moved},
                                  {"rebalance_s", r.seconds},
                                  {"imbalance_before", r.imbalance_before},
                                  {"imbalance_after", r.imbalance_after}});
        j["decomposition"] = {{"kind", to_string(c.decomposition)},
                              {"rebalance_every_steps", c.rebalance_every},
                              {"weights",
                               {{"fluid", c.balance.fluid},
                                {"walls", c.balance.walls},
                                {"source", c.balance.source}}},
                              {"final_cuts", run.final_cuts},
                              {"rebalances", rebalances}};
    }

    nlohmann::json totals;
    for (std::size_t k = 0; k < phase_keys.size(); ++k) {
        std::vector<double> v;
        for (const auto &t : run.timers)
            v.push_back(t[k]);
        totals["timers"][phase_keys[k]] = min_avg_max(v);
    }
    totals["idle_s"] = min_avg_max(run.idle_s);
    j["totals"] = totals;

    for (const auto &iv : run.intervals) {
        nlohmann::json jiv{{"step", iv.step}, {"time_s", iv.time_s}, {"columns", iv.columns}};
        if (!iv.column_interactions.empty()) {
            jiv["column_interactions"] = iv.column_interactions;
            jiv["column_descents"] = iv.column_descents;
        }
        for (const auto &r : iv.ranks) {
            nlohmann::json jr{{"steps", r.steps},
                              {"field", r.field},
                              {"virtual", r.virtual_},
                              {"ghost", r.ghost},
                              {"pairs", r.pairs},
                              {"interactions", r.interactions},
                              {"exported", r.exported},
                              {"migrated", r.migrated},
                              {"cell_moves", r.cell_moves},
                              {"idle_s", r.idle_s},
                              {"escaped", r.escaped},
                              {"reflected", r.reflected},
                              {"field_mean", r.field_mean},
                              {"messages", r.messages},
                              {"message_bytes", r.message_bytes},
                              {"comm_predict_s", r.comm_predict_s},
                              {"comm_predict_exchange_s", r.comm_predict_exchange_s},
                              {"comm_hockney_s", r.comm_hockney_s},
                              {"overlap_s", r.overlap_s},
                              {"comm_hidden_predict_s", r.hidden_predict_s},
                              {"halo_comm_s", r.halo_comm_s()},
                              {"probe_shift_s", r.probe_shift_s},
                              {"gauge_cpu_s", r.gauge_cpu_s},
                              {"gauge_samples", r.gauge_samples},
                              {"core_round_trip_s", r.core_round_trip_s},
                              {"core_round_trip_samples", r.core_round_trip_samples},
                              {"descents", r.descents},
                              {"rss_bytes", r.rss_bytes}};
            for (std::size_t k = 0; k < phase_keys.size(); ++k)
                jr["timers"][phase_keys[k]] = r.timers[k];
            for (std::size_t k = 0; k < shift_keys.size(); ++k) {
                auto &js = jr["shifts"][shift_keys[k]];
                js = {{"comm_s", r.shift_comm_s[k]},
                      {"comm_predict_s", r.shift_predict_s[k]},
                      {"comm_predict_own_kind_gap_s", r.shift_predict_own_kind_s[k]}};
                if (c.machine) // measured with --machine only (Domain::enable_cpu_segments)
                    js["cpu_before_s"] = r.segment_cpu_s[k];
            }
            jiv["ranks"].push_back(jr);
        }
        j["intervals"].push_back(jiv);
    }
    j["physics"] = {{"time_s", run.physics.time_s},
                    {"front_x", run.physics.front_x},
                    {"mass", run.physics.mass},
                    {"kinetic_energy", run.physics.kinetic_energy}};
    return j;
}

} // namespace sphperf::sph
