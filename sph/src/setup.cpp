#include "sphperf/sph/setup.hpp"

#include <cmath>

namespace sphperf::sph {

std::vector<ParticleRecord> make_fluid(const Geometry &geo, const Physics &phys) {
    std::vector<ParticleRecord> out;
    out.reserve(static_cast<std::size_t>(geo.fluid_particles()));
    const double top = geo.dam_y0 + (geo.fluid_rows - 1) * phys.delta;
    std::int64_t id = 0;
    for (int i = 0; i < geo.fluid_columns; ++i)
        for (int j = 0; j < geo.fluid_rows; ++j) {
            const double x = geo.dam_x0 + i * phys.delta, y = geo.dam_y0 + j * phys.delta;
            const double pressure = phys.rho0 * phys.gravity * (top - y);
            const double rho = phys.density(pressure);
            out.push_back(
                {x, y, 0, 0, rho, phys.pressure(rho), phys.particle_mass(), id++, Kind::fluid});
        }
    return out;
}

int wall_layers(const Physics &phys) {
    return static_cast<int>(std::ceil(phys.cell_size() / phys.delta - 1e-9));
}

std::vector<ParticleRecord> make_walls(const Geometry &geo, const Physics &phys,
                                       std::int64_t first_id) {
    // Layers at (k + 1/2) delta outside the wall surfaces x = 0, x = B and y = 0, so the fluid,
    // whose first particles sit delta / 2 inside, is one spacing from the first layer.
    std::vector<ParticleRecord> out;
    const int layers = wall_layers(phys);
    const double d = phys.delta;
    const double top = geo.dam_y0 + (geo.fluid_rows - 1) * d;
    std::int64_t id = first_id;
    auto add = [&](double x, double y) {
        // Hydrostatic start, so the walls hold the column from the first step.
        const double pressure = phys.rho0 * phys.gravity * std::max(0.0, top - y);
        const double rho = phys.density(pressure);
        out.push_back(
            {x, y, 0, 0, rho, phys.pressure(rho), phys.particle_mass(), id++, Kind::boundary});
    };
    const double reach = (layers - 0.5) * d; // outermost layer
    for (int k = 0; k < layers; ++k) {
        const double off = (k + 0.5) * d;
        for (double x = -reach; x <= geo.tank_length + reach + 1e-9; x += d) // floor and corners
            add(x, -off);
        for (double y = d / 2; y <= geo.ceiling + 1e-9; y += d) { // side walls
            add(-off, y);
            add(geo.tank_length + off, y);
        }
    }
    return out;
}

std::size_t add_mirrors(Particles &p, const Geometry &geo, const Physics &phys,
                        std::int64_t first_mirror_id, std::vector<std::uint32_t> &sources) {
    sources.clear();
    const double reach = phys.cell_size();
    const double right = geo.tank_length;
    std::size_t added = 0;
    for (std::size_t i = 0; i < p.fluid(); ++i) {
        const double x = p.x[i], y = p.y[i];
        const bool left_near = x < reach, right_near = right - x < reach, floor_near = y < reach;
        if (!left_near && !right_near && !floor_near)
            continue;
        ParticleRecord r = p.record(i);
        r.kind = Kind::mirror;
        const std::int64_t base = first_mirror_id + 3 * p.id[i];
        const double wall_x = left_near ? -x : 2 * right - x;
        if (left_near || right_near) { // image across the nearer side wall
            p.add_transient({wall_x, y, -r.vx, r.vy, r.rho, r.p, r.mass, base, Kind::mirror});
            sources.push_back(static_cast<std::uint32_t>(i));
            ++added;
        }
        if (floor_near) {
            p.add_transient({x, -y, r.vx, -r.vy, r.rho, r.p, r.mass, base + 1, Kind::mirror});
            sources.push_back(static_cast<std::uint32_t>(i));
            ++added;
        }
        if (floor_near && (left_near || right_near)) { // corner image
            p.add_transient({wall_x, -y, -r.vx, -r.vy, r.rho, r.p, r.mass, base + 2, Kind::mirror});
            sources.push_back(static_cast<std::uint32_t>(i));
            ++added;
        }
    }
    return added;
}

} // namespace sphperf::sph

namespace sphperf::sph {

std::size_t reflect_at_walls(Particles &p, const Geometry &geo) {
    std::size_t reflected = 0;
    for (std::size_t i = 0; i < p.fluid(); ++i) {
        bool hit = false;
        if (p.x[i] < 0) {
            p.x[i] = -p.x[i];
            p.vx[i] = -p.vx[i];
            hit = true;
        } else if (p.x[i] > geo.tank_length) {
            p.x[i] = 2 * geo.tank_length - p.x[i];
            p.vx[i] = -p.vx[i];
            hit = true;
        }
        if (p.y[i] < 0) {
            p.y[i] = -p.y[i];
            p.vy[i] = -p.vy[i];
            hit = true;
        }
        reflected += hit;
    }
    return reflected;
}

void refresh_mirrors(Particles &p, std::size_t first, const std::vector<std::uint32_t> &sources) {
    for (std::size_t k = 0; k < sources.size(); ++k)
        p.rho[first + k] = p.rho[sources[k]];
}

} // namespace sphperf::sph
