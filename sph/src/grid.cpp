#include "sphperf/sph/grid.hpp"

#include <bit>
#include <stdexcept>

namespace sphperf::sph {

void CellList::update(const Particles &p, const CellWindow &w) {
    const std::size_t n = p.size();
    head_.assign(static_cast<std::size_t>(w.cells()), -1);
    next_.resize(n);
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i) {
        std::atomic_ref<std::int32_t> head(
            head_[static_cast<std::size_t>(w.cell_of(p.x[i], p.y[i]))]);
        next_[i] = head.exchange(static_cast<std::int32_t>(i), std::memory_order_relaxed);
    }
    moves_ = n; // every particle is filed anew each step
}

void CellTable::ensure_ids(std::int64_t id) {
    if (id < 0)
        throw std::logic_error("particle ids must be non-negative");
    const auto need = static_cast<std::size_t>(id) + 1;
    if (need > home_.size()) {
        const std::size_t size = std::max(need, 2 * home_.size());
        home_.resize(size, -1);
        slot_.resize(size, 0);
    }
}

void CellTable::insert(std::int64_t id, std::uint32_t index, std::int32_t cell) {
    auto &members = cells_[static_cast<std::size_t>(cell)];
    home_[static_cast<std::size_t>(id)] = cell;
    slot_[static_cast<std::size_t>(id)] = static_cast<std::uint32_t>(members.size());
    members.push_back({id, index});
}

void CellTable::update(const Particles &p, const CellWindow &w) {
    if (window_cells_ != w.cells()) { // first call, or a new window: start over
        cells_.assign(static_cast<std::size_t>(w.cells()), {});
        std::fill(home_.begin(), home_.end(), -1);
        window_cells_ = w.cells();
    }
    const std::size_t n = p.size();
    std::int64_t max_id = -1;
    for (std::size_t i = 0; i < n; ++i)
        max_id = std::max(max_id, p.id[i]);
    if (max_id >= 0)
        ensure_ids(max_id);
    new_cell_.resize(n);
    // Particles that stay refresh their index in place (distinct members: no race); the few
    // that change cell move serially afterwards.
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i) {
        const auto id = static_cast<std::size_t>(p.id[i]);
        new_cell_[i] = w.cell_of(p.x[i], p.y[i]);
        if (home_[id] == new_cell_[i])
            cells_[static_cast<std::size_t>(home_[id])][slot_[id]].index =
                static_cast<std::uint32_t>(i);
    }
    moves_ = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const std::int64_t id = p.id[i];
        if (home_[static_cast<std::size_t>(id)] == new_cell_[i])
            continue;
        forget(id);
        insert(id, static_cast<std::uint32_t>(i), new_cell_[i]);
        ++moves_;
    }
}

std::vector<std::int64_t> CellTable::save_state() const {
    std::vector<std::int64_t> s{window_cells_};
    for (const auto &members : cells_) {
        s.push_back(static_cast<std::int64_t>(members.size()));
        for (const Member &m : members) {
            s.push_back(m.id);
            s.push_back(m.index);
        }
    }
    return s;
}

void CellTable::restore_state(const std::vector<std::int64_t> &s) {
    const auto bad = [] { return std::runtime_error("checkpoint: malformed Cell+Table state"); };
    if (s.empty())
        throw bad();
    window_cells_ = static_cast<int>(s[0]);
    if (window_cells_ < 0)
        throw bad();
    cells_.assign(static_cast<std::size_t>(window_cells_), {});
    std::fill(home_.begin(), home_.end(), -1);
    std::size_t k = 1;
    for (std::size_t c = 0; c < cells_.size(); ++c) {
        if (k >= s.size() || s[k] < 0 || static_cast<std::size_t>(s[k]) > (s.size() - k - 1) / 2)
            throw bad();
        const auto n = static_cast<std::size_t>(s[k++]);
        for (std::size_t i = 0; i < n; ++i, k += 2) {
            if (s[k] < 0 || s[k + 1] < 0)
                throw bad();
            ensure_ids(s[k]);
            insert(s[k], static_cast<std::uint32_t>(s[k + 1]), static_cast<std::int32_t>(c));
        }
    }
    if (k != s.size())
        throw bad();
}

void CellTable::remove_transient(const Particles &p, const CellWindow &) {
    for (std::size_t i = p.owned(); i < p.size(); ++i)
        forget(p.id[i]);
}

void CellTable::forget(std::int64_t id) {
    if (id < 0 || static_cast<std::size_t>(id) >= home_.size())
        return;
    const auto uid = static_cast<std::size_t>(id);
    if (home_[uid] < 0)
        return;
    // Swap-remove: the cell's last member takes the hole.
    auto &members = cells_[static_cast<std::size_t>(home_[uid])];
    const std::uint32_t hole = slot_[uid];
    members[hole] = members.back();
    slot_[static_cast<std::size_t>(members[hole].id)] = hole;
    members.pop_back();
    home_[uid] = -1;
}

} // namespace sphperf::sph
