#include "sphperf/sph/sorted.hpp"

#include <algorithm>
#include <cmath>

namespace sphperf::sph {

void CellSorted::update(const Particles &p, const CellWindow &w) {
    const std::size_t n = p.size();
    cols_ = w.cols();
    rows_ = w.rows();
    const auto cells = static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_);
    owned_ = p.owned();
    key_.resize(n);
    start_.assign(cells + 1, 0);
    for (std::size_t i = 0; i < n; ++i) {
        const auto k = static_cast<std::uint32_t>((w.column_of(p.x[i]) - w.col_begin) * rows_ +
                                                  (w.row_of(p.y[i]) - w.row_begin));
        key_[i] = k;
        ++start_[k + 1];
    }
    for (std::size_t c = 0; c < cells; ++c)
        start_[c + 1] += start_[c];
    // Counting sort by cell, then by id within a cell (a few particles: insertion sort).
    orig_.resize(n);
    fill_.assign(start_.begin(), start_.end() - 1);
    for (std::size_t i = 0; i < n; ++i)
        orig_[fill_[key_[i]]++] = static_cast<std::uint32_t>(i);
#pragma omp parallel for schedule(dynamic, 64)
    for (std::size_t c = 0; c < cells; ++c) {
        const auto b = orig_.begin() + start_[c], e = orig_.begin() + start_[c + 1];
        for (auto it = b + (b != e); it < e; ++it)
            for (auto j = it; j > b && p.id[*(j - 1)] > p.id[*j]; --j)
                std::iter_swap(j - 1, j);
    }
    for (auto *v : {&x_, &y_, &vx_, &vy_, &rho_, &p_, &mass_, &fluid_})
        v->resize(n);
    id_.resize(n);
#pragma omp parallel for schedule(static)
    for (std::size_t s = 0; s < n; ++s) {
        const std::uint32_t i = orig_[s];
        x_[s] = p.x[i];
        y_[s] = p.y[i];
        vx_[s] = p.vx[i];
        vy_[s] = p.vy[i];
        mass_[s] = p.mass[i];
        fluid_[s] = p.kind[i] == Kind::fluid ? 1.0 : 0.0;
        id_[s] = p.id[i];
    }
    moves_ = n; // every particle is filed anew each step
    // Density and pressure are copied by refresh_density once they are final for the pass
    // that reads them (the density pass reads neither).
}

void CellSorted::refresh_density(const Particles &p) {
    const std::size_t n = orig_.size();
#pragma omp parallel for schedule(static)
    for (std::size_t s = 0; s < n; ++s) {
        rho_[s] = p.rho[orig_[s]];
        p_[s] = p.p[orig_[s]];
    }
}

CellSorted::View CellSorted::view() const {
    return {x_.data(),     y_.data(),    vx_.data(),    vy_.data(), rho_.data(),
            p_.data(),     mass_.data(), fluid_.data(), id_.data(), orig_.data(),
            start_.data(), cols_,        rows_,         owned_};
}

namespace {

// Added to squared distances before the square root (below their rounding unit, so it changes
// no distance but 0, and pairs at distance 0 are masked out):
// every lane then computes finite terms and no arithmetic is conditional.
constexpr double tiny = 1e-150;

constexpr int lanes = 8; // one AVX-512 vector of doubles; fixed, so sums do not depend on ISA

// A sum split over a fixed number of lanes by position within each range, then added in a
// fixed tree: deterministic for given range contents, and the inner loop vectorises.
struct LaneSum {
    double v[lanes] = {};
    double total() const {
        return ((v[0] + v[1]) + (v[2] + v[3])) + ((v[4] + v[5]) + (v[6] + v[7]));
    }
};

// Calls body(s, lane) for every sorted position s of the 3 x 3 cells around cell (col, row):
// columns west to east, each one contiguous range (cells are numbered column by column).
template <class Body>
void for_each_candidate(const CellSorted::View &v, int col, int row, Body &&body) {
    const int r0 = std::max(row - 1, 0), r1 = std::min(row + 1, v.rows - 1);
    for (int c = std::max(col - 1, 0); c <= std::min(col + 1, v.cols - 1); ++c) {
        std::uint32_t s = v.start[c * v.rows + r0];
        const std::uint32_t e = v.start[c * v.rows + r1 + 1];
        for (; s + lanes <= e; s += lanes) {
#pragma omp simd
            for (int l = 0; l < lanes; ++l)
                body(s + static_cast<std::uint32_t>(l), l);
        }
        for (int l = 0; s < e; ++s, ++l)
            body(s, l);
    }
}

// Runs per_particle(view, sorted index, col, row) for every owned particle, cells shared out
// dynamically (the water is not spread evenly over cells).
template <class F> void for_each_owned(const CellSorted::View &v, F &&per_particle) {
    const int cells = v.cols * v.rows;
#pragma omp parallel for schedule(dynamic, 8)
    for (int cell = 0; cell < cells; ++cell) {
        const int col = cell / v.rows, row = cell % v.rows;
        for (std::uint32_t s = v.start[cell]; s < v.start[cell + 1]; ++s)
            if (v.orig[s] < v.owned)
                per_particle(s, col, row);
    }
}
} // namespace

void continuity(Particles &p, SortedNeighbours &nb, const Physics &phys, double back) {
    const CellSorted::View v = nb.grid->view();
    const BranchFreeKernel k(phys.kernel());
    const double r2max = phys.cell_size() * phys.cell_size();
    std::uint64_t pairs = 0, interactions = 0;
    const int cells = v.cols * v.rows;
#pragma omp parallel for schedule(dynamic, 8) reduction(+ : pairs, interactions)
    for (int cell = 0; cell < cells; ++cell) {
        const int col = cell / v.rows, row = cell % v.rows;
        for (std::uint32_t i = v.start[cell]; i < v.start[cell + 1]; ++i) {
            if (v.orig[i] >= v.owned)
                continue;
            const double xi = v.x[i], yi = v.y[i], vxi = v.vx[i], vyi = v.vy[i];
            const double fi = v.fluid[i];
            const std::int64_t idi = v.id[i];
            LaneSum drho;
            int inter[lanes] = {}, pair[lanes] = {};
            for_each_candidate(v, col, row, [&](std::uint32_t j, int l) {
                const double dx = xi - v.x[j], dy = yi - v.y[j];
                const double d2 = dx * dx + dy * dy;
                const bool in = (d2 < r2max) & (j != i) & (fi + v.fluid[j] > 0);
                const bool act = in & (d2 > 0); // coincident images have no direction
                // Neighbours by the end of the step, the rate at separations `back` earlier
                // (physics.hpp continuity_term).
                const double dvx = vxi - v.vx[j], dvy = vyi - v.vy[j];
                const double mx = dx - back * dvx, my = dy - back * dvy;
                const double r = std::sqrt(mx * mx + my * my + tiny); // finite, masked below
                const double f = k.derivative(r) / r;
                const double term = v.mass[j] * f * (dvx * mx + dvy * my);
                drho.v[l] += act ? term : 0.0;
                inter[l] += in;
                pair[l] += in & ((v.orig[j] >= v.owned) | (v.id[j] > idi));
            });
            p.drho[v.orig[i]] = drho.total();
            for (int l = 0; l < lanes; ++l) {
                interactions += static_cast<std::uint64_t>(inter[l]);
                pairs += static_cast<std::uint64_t>(pair[l]);
            }
        }
    }
    nb.counts = {pairs, interactions};
}

void momentum(Particles &p, SortedNeighbours &nb, const Physics &phys) {
    nb.grid->refresh_density(p);
    const CellSorted::View v = nb.grid->view();
    const BranchFreeKernel k(phys.kernel());
    const double r2max = phys.cell_size() * phys.cell_size();
    const double h = k.h, eta2 = 0.01 * h * h, alpha_c0 = phys.alpha * phys.c0;
    for_each_owned(v, [&](std::uint32_t i, int col, int row) {
        const std::uint32_t oi = v.orig[i];
        if (v.fluid[i] == 0) { // wall particles do not move
            p.ax[oi] = 0;
            p.ay[oi] = 0;
            return;
        }
        const double xi = v.x[i], yi = v.y[i], vxi = v.vx[i], vyi = v.vy[i];
        const double rhoi = v.rho[i], pi_rho2 = v.p[i] / (rhoi * rhoi);
        LaneSum ax, ay;
        for_each_candidate(v, col, row, [&](std::uint32_t j, int l) {
            const double dx = xi - v.x[j], dy = yi - v.y[j];
            const double d2 = dx * dx + dy * dy;
            const bool act = (d2 < r2max) & (j != i) & (d2 > 0); // i is fluid: every j interacts
            const double r = std::sqrt(d2 + tiny);               // finite terms, masked below
            const double f = k.derivative(r) / r;
            const double vdotr = (vxi - v.vx[j]) * dx + (vyi - v.vy[j]) * dy;
            // Viscosity for approaching pairs only (vdotr < 0): clamping vdotr rather than
            // branching keeps the loop branch-free; receding pairs get mu = 0.
            const double mu = h * std::min(vdotr, 0.0) / (r * r + eta2);
            const double rhoj = v.rho[j];
            const double visc = -alpha_c0 * mu / (0.5 * (rhoi + rhoj));
            const double coef = v.mass[j] * (pi_rho2 + v.p[j] / (rhoj * rhoj) + visc);
            // A multiplied mask, not a select: GCC turns the select into a conditional store
            // here, which does not vectorise. Every term is finite, so 0 x term adds nothing.
            const double mask = act ? 1.0 : 0.0;
            ax.v[l] += mask * (-coef * f * dx);
            ay.v[l] += mask * (-coef * f * dy);
        });
        p.ax[oi] = ax.total();
        p.ay[oi] = ay.total() - phys.gravity;
    });
}

void shepard_filter(Particles &p, SortedNeighbours &nb, const Physics &phys) {
    nb.grid->refresh_density(p);
    const CellSorted::View v = nb.grid->view();
    const BranchFreeKernel k(phys.kernel());
    const double r2max = phys.cell_size() * phys.cell_size();
    const double w0 = k.value(0.0);
    std::vector<double> filtered(p.owned(), 0.0);
    for_each_owned(v, [&](std::uint32_t i, int col, int row) {
        if (v.fluid[i] == 0)
            return; // wall densities follow the continuity equation
        const double xi = v.x[i], yi = v.y[i];
        LaneSum num, den;
        for_each_candidate(v, col, row, [&](std::uint32_t j, int l) {
            const double dx = xi - v.x[j], dy = yi - v.y[j];
            const double d2 = dx * dx + dy * dy;
            const bool in = (d2 < r2max) & (j != i);
            const double wr = k.value(std::sqrt(d2)); // 0 beyond the support anyway
            const double w = in ? wr : 0.0;
            num.v[l] += v.mass[j] * w;
            den.v[l] += v.mass[j] / v.rho[j] * w;
        });
        filtered[v.orig[i]] =
            (v.mass[i] * w0 + num.total()) / (v.mass[i] / v.rho[i] * w0 + den.total());
    });
    for (std::size_t i = 0; i < p.fluid(); ++i)
        p.rho[i] = filtered[i];
}

} // namespace sphperf::sph
