#pragma once
// Particle storage in structure-of-arrays order. Owned particles (fluid, then wall particles of
// the fixed boundary) come first; transient ones (mirrored virtual particles and ghosts, i.e.
// copies of a neighbouring rank's particles that keep their kind) are appended each step and
// dropped at its end. Ids are dense and global, so a ghost has its owner's id.
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace sphperf::sph {

enum class Kind : std::uint8_t {
    fluid = 0,    // field particle
    boundary = 1, // fixed wall particle (Dirichlet), owned, density evolves (dynamic boundary)
    mirror = 2,   // virtual particle mirrored from near-wall fluid each step (Neumann)
};

// One particle by value: what crosses ranks and what tests build configurations from.
struct ParticleRecord {
    double x, y, vx, vy, rho, p, mass;
    std::int64_t id;
    Kind kind;
};

class Particles {
public:
    std::vector<double> x, y, vx, vy, rho, p, mass;
    std::vector<double> ax, ay, drho; // time derivatives
    std::vector<std::int64_t> id;
    std::vector<Kind> kind;

    std::size_t size() const { return x.size(); }
    std::size_t owned() const { return owned_; }
    std::size_t fluid() const { return fluid_; }

    // Adds an owned particle; fluid particles are kept in front of boundary particles.
    void add_owned(const ParticleRecord &r);
    // Appends a transient particle (a mirror, or a ghost of any kind) after all owned ones.
    void add_transient(const ParticleRecord &r);
    void drop_transient();
    // Removes owned particle i (a migrating particle) keeping fluid-before-boundary order.
    void remove_owned(std::size_t i);
    ParticleRecord record(std::size_t i) const;
    void reserve(std::size_t n);
    // Reorders the owned particles, every array: position k takes old particle order[k]. Only
    // while no transient particles exist (their indices would go stale), and order must keep
    // fluid before walls; anything else throws.
    void permute(std::span<const std::uint32_t> order);

private:
    void push(const ParticleRecord &r);
    void assign(std::size_t i, const ParticleRecord &r);
    std::size_t owned_ = 0;
    std::size_t fluid_ = 0;
    // permute's buffers, kept: it runs every step or so.
    std::vector<double> scratch_;
    std::vector<std::int64_t> scratch_id_;
    std::vector<Kind> scratch_kind_;
    std::vector<std::uint8_t> seen_;
};

} // namespace sphperf::sph
