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

void IdTable::grow() {
    std::vector<std::int64_t> old = std::move(slots_);
    const std::size_t capacity = old.empty() ? 16 : 2 * old.size();
    slots_.assign(capacity, empty);
    shift_ = 64 - std::countr_zero(capacity);
    size_ = 0;
    for (std::int64_t k : old)
        if (k != empty)
            insert(k);
}

void IdTable::insert(std::int64_t id) {
    if (2 * (size_ + 1) > slots_.size()) // keep the load factor <= 1/2
        grow();
    const std::size_t mask = slots_.size() - 1;
    for (std::size_t s = slot_of(id);; s = (s + 1) & mask) {
        if (slots_[s] == id)
            return;
        if (slots_[s] == empty) {
            slots_[s] = id;
            ++size_;
            return;
        }
    }
}

bool IdTable::erase(std::int64_t id) {
    if (slots_.empty())
        return false;
    const std::size_t mask = slots_.size() - 1;
    std::size_t s = slot_of(id);
    while (slots_[s] != id) {
        if (slots_[s] == empty)
            return false;
        s = (s + 1) & mask;
    }
    // Backward-shift: pull later members of the probe run into the hole.
    std::size_t hole = s;
    for (std::size_t t = (hole + 1) & mask; slots_[t] != empty; t = (t + 1) & mask) {
        const std::size_t home = slot_of(slots_[t]);
        // Move slots_[t] into the hole unless its home lies cyclically in (hole, t].
        const bool stays = hole <= t ? (hole < home && home <= t) : (hole < home || home <= t);
        if (!stays) {
            slots_[hole] = slots_[t];
            hole = t;
        }
    }
    slots_[hole] = empty;
    --size_;
    return true;
}

void CellTable::ensure_ids(std::int64_t id) {
    if (id < 0)
        throw std::logic_error("particle ids must be non-negative");
    const auto need = static_cast<std::size_t>(id) + 1;
    if (need > home_.size()) {
        const std::size_t size = std::max(need, 2 * home_.size());
        home_.resize(size, -1);
        index_of_.resize(size, -1);
    }
}

void CellTable::update(const Particles &p, const CellWindow &w) {
    if (window_cells_ != w.cells()) { // first call, or a new window: start over
        tables_.assign(static_cast<std::size_t>(w.cells()), IdTable{});
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
    // Cell of every particle in parallel; the (few) moves between tables serially.
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i) {
        new_cell_[i] = w.cell_of(p.x[i], p.y[i]);
        index_of_[static_cast<std::size_t>(p.id[i])] = static_cast<std::int32_t>(i);
    }
    moves_ = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const auto id = static_cast<std::size_t>(p.id[i]);
        if (home_[id] == new_cell_[i])
            continue;
        if (home_[id] >= 0)
            tables_[static_cast<std::size_t>(home_[id])].erase(p.id[i]);
        tables_[static_cast<std::size_t>(new_cell_[i])].insert(p.id[i]);
        home_[id] = new_cell_[i];
        ++moves_;
    }
}

void CellTable::remove_transient(const Particles &p, const CellWindow &) {
    for (std::size_t i = p.owned(); i < p.size(); ++i)
        forget(p.id[i]);
}

void CellTable::forget(std::int64_t id) {
    if (id < 0 || static_cast<std::size_t>(id) >= home_.size())
        return;
    auto &home = home_[static_cast<std::size_t>(id)];
    if (home >= 0)
        tables_[static_cast<std::size_t>(home)].erase(id);
    home = -1;
}

} // namespace sphperf::sph
