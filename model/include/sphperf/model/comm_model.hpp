#pragma once
// Cost of one MPI message on this machine: the piecewise Hockney model of machine.json (both
// pieces and the eager/rendezvous breakpoint, per measured rank pair and per locality class),
// so a 17 KB ghost message is costed with the piece its size falls in.
#include "sphperf/model/hockney.hpp"

#include <algorithm>
#include <array>
#include <memory>
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace sphperf::model {

struct Link {
    std::string locality;
    int pu_a = -1, pu_b = -1; // processing units of the two ranks as ping-pong placed them
    PiecewiseFit fit;
};

class CommModel {
public:
    // Reads the "hockney" section of a machine profile; throws UsageError naming the key.
    static CommModel from_profile(const nlohmann::json &machine);

    // The link between two processing units of one node (OS indices, -1 when unbound): the
    // measured pair on exactly those units when there is one, otherwise the slowest measured
    // locality class within a node, so an unbound or unmeasured placement is never costed
    // optimistically (and never as a network hop).
    const Link &link(int pu_a, int pu_b) const;
    // One-way time of a message of `bytes` between two units.
    double seconds(int pu_a, int pu_b, double bytes) const {
        return link(pu_a, pu_b).fit.predict(bytes);
    }
    // One MPI_Sendrecv that sends `out` bytes and receives `in` bytes: both travel at once, the
    // call lasts as long as the longer one. A missing side (tank edge) is passed as a negative.
    double sendrecv_seconds(int pu, int pu_out, double out, int pu_in, double in) const;

    const std::vector<Link> &pairs() const { return pairs_; }
    const std::vector<Link> &classes() const { return classes_; }
    const Link &slowest_class() const { return classes_[slowest_]; }
    // The locality class of that name ("other_node", ...), or null when it was not measured.
    const Link *class_named(const std::string &name) const;

private:
    std::vector<Link> pairs_, classes_;
    std::size_t slowest_ = 0;
};

// The app's halo exchange as the `exchange` benchmark measured it (machine.json "exchange"):
// the mean cost of one shift (handshake excluded: counts and payloads both ways) by the gap of
// compute before it and the payload, per rank count, and the round overhead of time-sharing.
// The mean, not the median: the model predicts sums and the cost has a heavy tail.
// Three tables: `blocking` points, a shift after compute; `following` points (exchange
// --following), a shift right after another one, with `gap_s` from the last of its kind (the
// compute and the shift before); `overlapped` points (exchange --overlapped), what sph --overlap
// leaves exposed of a shift, posting the payloads and completing the receives, with `gap_s` the
// compute behind them.
enum class ShiftMode { blocking, following, overlapped };
struct ExchangePoint {
    double gap_s = 0, bytes = 0, mean_s = 0, median_s = 0, overhead = 0; // overhead 0: unknown
    ShiftMode mode = ShiftMode::blocking;
};
// Which compute gap costs a blocking shift within the cores (app_shift_seconds).
enum class GapRule { any_shift, own_kind_gap };

// One set's points arranged for lookups: per mode the payloads measured (in the points' order),
// and per payload its (log gap, mean seconds) sorted by gap. The app costs every shift it makes
// with them (sph --machine); arranging the points anew at each call cost about 11 us of each
// step on 2 ranks, outside every timer (model/NOTES.md, session 84).
struct ShiftTables {
    struct Curve {
        double bytes = 0;
        std::vector<std::pair<double, double>> log_gap_mean;
    };
    std::array<std::vector<Curve>, 3> by_mode; // indexed by ShiftMode
    static ShiftTables of(const std::vector<ExchangePoint> &points);
};

struct ExchangeSet {
    int ranks = 0, cores = 0;
    std::vector<ExchangePoint> points;
    // Built from `points` by ExchangeModel::from_profile; a set assembled by hand has none, and
    // shift_seconds then arranges its points at each call.
    std::shared_ptr<const ShiftTables> tables;
    double load() const { return static_cast<double>(ranks) / cores; }
    bool has(ShiftMode mode) const {
        return std::any_of(points.begin(), points.end(),
                           [mode](const ExchangePoint &p) { return p.mode == mode; });
    }
};

class ExchangeModel {
public:
    // Reads machine.json's "exchange" section; none gives an empty model.
    static ExchangeModel from_profile(const nlohmann::json &machine);
    bool empty() const { return sets_.empty(); }
    // The measured rank count nearest in load (ranks x threads / cores) to the one asked for.
    const ExchangeSet &set_for(int ranks, int threads, int cores) const;
    // Mean seconds of one shift after `gap_s` of compute, carrying `bytes` per payload:
    // log-linear in the gap between measured gaps (held at the ends), linear in the payload.
    // Other modes read their own table (the set must have its points): `overlapped`, the
    // exposed part of an overlapped shift with `gap_s` of compute behind it.
    static double shift_seconds(const ExchangeSet &set, double gap_s, double bytes,
                                ShiftMode mode = ShiftMode::blocking);
    // One of the app's shifts, `since_any_s` after its previous shift of any kind and
    // `since_kind_s` after the previous one of its own kind (migration, ghosts, densities).
    // The compute since the last shift of any kind decides: every message now takes the same
    // eager path (scripts/mpirun.sh), so any shift warms it (session 32; until then the gap
    // since the same kind, measured when large ghosts took another protocol). A shift within a
    // tenth of its own kind's gap after the one before (the ghosts, packed right after the
    // migration) reads the following table at its own kind's gap when the set has one, else
    // the blocking table there: the back-to-back point is far too cheap for it (sessions 19
    // and 29). Above the cores the gap since any shift decides: the shift waits for a
    // neighbour descheduled behind the compute since the last exchange of any kind.
    // `rule` own_kind_gap: sessions 19-31's rule, the blocking shifts within the cores at the
    // gap since their own kind, which every report records beside (the untuned comparison).
    static double app_shift_seconds(const ExchangeSet &set, double since_any_s, double since_kind_s,
                                    double bytes, GapRule rule = GapRule::any_shift);
    // Round time over the time-sharing bound (>= 1 when measured), at that gap; 1 when the set
    // is not oversubscribed or has no figure.
    static double round_overhead(const ExchangeSet &set, double gap_s);
    const std::vector<ExchangeSet> &sets() const { return sets_; }

private:
    std::vector<ExchangeSet> sets_;
};

// The JSON form of a fit (pieces + breakpoint), as machine.json stores it, and back.
nlohmann::json to_json(const PiecewiseFit &fit);
PiecewiseFit piecewise_from_json(const nlohmann::json &j, const std::string &where);

} // namespace sphperf::model
