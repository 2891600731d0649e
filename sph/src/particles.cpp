#include "sphperf/sph/particles.hpp"

#include <stdexcept>
#include <string>

namespace sphperf::sph {

void Particles::push(const ParticleRecord &r) {
    x.push_back(r.x);
    y.push_back(r.y);
    vx.push_back(r.vx);
    vy.push_back(r.vy);
    rho.push_back(r.rho);
    p.push_back(r.p);
    mass.push_back(r.mass);
    ax.push_back(0);
    ay.push_back(0);
    drho.push_back(0);
    id.push_back(r.id);
    kind.push_back(r.kind);
}

void Particles::assign(std::size_t i, const ParticleRecord &r) {
    x[i] = r.x;
    y[i] = r.y;
    vx[i] = r.vx;
    vy[i] = r.vy;
    rho[i] = r.rho;
    p[i] = r.p;
    mass[i] = r.mass;
    ax[i] = ay[i] = drho[i] = 0;
    id[i] = r.id;
    kind[i] = r.kind;
}

ParticleRecord Particles::record(std::size_t i) const {
    return {x[i], y[i], vx[i], vy[i], rho[i], p[i], mass[i], id[i], kind[i]};
}

void Particles::reserve(std::size_t n) {
    for (auto *v : {&x, &y, &vx, &vy, &rho, &p, &mass, &ax, &ay, &drho})
        v->reserve(n);
    id.reserve(n);
    kind.reserve(n);
}

void Particles::add_owned(const ParticleRecord &r) {
    if (size() != owned_)
        throw std::logic_error("owned particles must be added before transient ones");
    if (r.kind != Kind::fluid && r.kind != Kind::boundary)
        throw std::logic_error("only fluid and boundary particles are owned");
    push(r);
    if (r.kind == Kind::fluid && fluid_ < owned_) {
        // Keep fluid first: move the first boundary particle to the end, put r in its place.
        const std::size_t last = size() - 1;
        const ParticleRecord b = record(fluid_);
        assign(fluid_, r);
        assign(last, b);
    }
    if (r.kind == Kind::fluid)
        ++fluid_;
    ++owned_;
}

void Particles::add_transient(const ParticleRecord &r) {
    push(r);
}

void Particles::drop_transient() {
    for (auto *v : {&x, &y, &vx, &vy, &rho, &p, &mass, &ax, &ay, &drho})
        v->resize(owned_);
    id.resize(owned_);
    kind.resize(owned_);
}

void Particles::remove_owned(std::size_t i) {
    if (size() != owned_)
        throw std::logic_error("remove owned particles only while no transient ones exist");
    if (i >= owned_)
        throw std::out_of_range("remove_owned index");
    if (kind[i] == Kind::fluid) {
        // Last fluid fills the hole, last owned fills the last fluid's slot.
        const std::size_t last_fluid = fluid_ - 1;
        assign(i, record(last_fluid));
        assign(last_fluid, record(owned_ - 1));
        --fluid_;
    } else {
        assign(i, record(owned_ - 1));
    }
    --owned_;
    drop_transient(); // shrinks every array to owned_
}

namespace {
template <class T>
void gather(std::vector<T> &v, std::span<const std::uint32_t> order, std::vector<T> &scratch) {
    // The buffer swapped in keeps v's capacity: transients appended next need no allocation.
    scratch.reserve(v.capacity());
    scratch.resize(order.size());
    for (std::size_t k = 0; k < order.size(); ++k)
        scratch[k] = v[order[k]];
    v.swap(scratch);
}
} // namespace

void Particles::permute(std::span<const std::uint32_t> order) {
    if (size() != owned_)
        throw std::logic_error("permute owned particles only while no transient ones exist");
    if (order.size() != owned_)
        throw std::logic_error("permute: an order of " + std::to_string(order.size()) +
                               " positions for " + std::to_string(owned_) + " particles");
    seen_.assign(owned_, 0);
    for (std::size_t k = 0; k < order.size(); ++k) {
        const std::uint32_t i = order[k];
        if (i >= owned_ || seen_[i] || (i < fluid_) != (k < fluid_))
            throw std::logic_error("permute: position " + std::to_string(k) + " takes particle " +
                                   std::to_string(i) +
                                   ", not a permutation keeping fluid before walls");
        seen_[i] = 1;
    }
    for (auto *v : {&x, &y, &vx, &vy, &rho, &p, &mass, &ax, &ay, &drho})
        gather(*v, order, scratch_);
    gather(id, order, scratch_id_);
    gather(kind, order, scratch_kind_);
}

} // namespace sphperf::sph
