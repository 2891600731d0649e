// sphmodel calibrate: the thesis regressions, the compute-cost fit with terms chosen by
// cross-validation, the roofline placement, the communication links and the workload traces.
#include "sphperf/errors.hpp"
#include "sphperf/model/jitter.hpp"
#include "sphperf/model/memory.hpp"
#include "sphperf/model/placement.hpp"
#include "sphperf/model/runtime.hpp"
#include "sphperf/stats.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <sstream>
#include <string_view>
#include <tuple>

namespace sphperf::model {

double RankWork::value(const std::string &term) const {
    if (term == "const")
        return 1.0;
    if (term == "interactions")
        return interactions;
    if (term == "owned")
        return field + walls;
    if (term == "ghost")
        return ghost;
    if (term == "cell_moves")
        return cell_moves;
    if (term == "walls")
        return walls;
    if (term == "descents")
        return descents;
    if (term == "core_round_trips")
        return core_round_trip_s;
    throw std::invalid_argument("unknown cost term " + term);
}

namespace {
using nlohmann::json;

json scatter_json(const LevelScatter &s) {
    return {{"log_sd", s.log_sd()}, {"dof", s.dof}, {"runs", s.runs}, {"sum_sq", s.sum_sq}};
}

// The calibration runs' scatter around their setup's level (run_level.scatter of each compute
// entry), pooled over the grids of one thread count: a table or list entry has 3 runs in 2
// setups, one degree of freedom, too few for a figure of its own, while the host's noise is
// shared by the grids run at the same thread count (model/NOTES.md, session 44). A prediction
// carries it as its band (predict: wall_band).
json pooled_level_scatter(const json &compute) {
    std::map<int, LevelScatter> by_threads;
    std::map<int, std::vector<std::string>> grids;
    for (const auto &c : compute) {
        const auto &sc = c.at("run_level").at("scatter");
        const int t = c.at("threads").get<int>();
        by_threads[t] += LevelScatter{sc.at("sum_sq").get<double>(), sc.at("dof").get<int>(),
                                      sc.at("runs").get<int>()};
        grids[t].push_back(c.at("grid").get<std::string>());
    }
    json per = json::array();
    for (const auto &[t, s] : by_threads) {
        json e = scatter_json(s);
        e["threads"] = t;
        e["grids"] = grids.at(t);
        per.push_back(e);
    }
    return {{"method", "per thread count, the pooled standard deviation of ln(measured / fitted "
                       "compute) of the calibration runs about their setup's mean, over the "
                       "grids' compute fits (degrees of freedom: runs less setups per fit); "
                       "predict gives each configuration a band of +-2 of it (wall_band)"},
            {"per_threads", per}};
}

// A compute entry's level record of one setup (run_level/per_setup/SETUP), or null.
const nlohmann::json *setup_level_of(const nlohmann::json &entry, const std::string &setup) {
    const auto &level = entry.at("run_level");
    if (!level.contains("per_setup") || !level.at("per_setup").contains(setup))
        return nullptr;
    return &level.at("per_setup").at(setup);
}
} // namespace

LinearFit compute_cost_of(const nlohmann::json &entry, const std::string &setup) {
    LinearFit f = LinearFit::from_json(entry, "model compute");
    if (const auto *s = setup_level_of(entry, setup))
        f = scaled(f, s->at("factor").get<double>() /
                          entry.at("run_level").at("factor").get<double>());
    return f;
}

namespace {
using nlohmann::json;

bool time_shared(const SphRun &r, int cores) {
    return r.config.ranks * r.config.threads > cores;
}

// The compute entry of a run's grid and thread count, nullptr when calibration has none.
const json *compute_entry(const json &compute, const SphRun &r) {
    for (const auto &c : compute)
        if (c.at("grid") == r.config.grid && c.at("threads") == r.config.threads)
            return &c;
    return nullptr;
}

// A rank-interval's mean core round trip (sph's core latency gauge), 0 where not measured.
double mean_round_trip(const RankStats &rk) {
    return rk.core_round_trip_samples > 0 ? rk.core_round_trip_s / rk.core_round_trip_samples : 0.0;
}

// The predicted compute per step of every rank of an interval.
std::vector<double> fitted_compute(const LinearFit &f, const IntervalStats &iv) {
    std::vector<double> out;
    for (const auto &rk : iv.ranks) {
        const RankWork w{rk.field_mean, rk.virtual_, rk.ghost,           rk.interactions,
                         rk.cell_moves, rk.descents, mean_round_trip(rk)};
        std::vector<double> x;
        for (const auto &t : f.terms)
            x.push_back(w.value(t));
        out.push_back(std::max(0.0, f.predict(x)));
    }
    return out;
}

struct Point {
    RankWork work;
    double pairs = 0, exported = 0, compute_s_per_step = 0;
    double froude_t = 0; // interval midpoint / sqrt(scale)
    int run = 0, ranks = 1;
};

// The Froude time of an interval's midpoint (simulated time / sqrt(scale)): where the cost
// fit's window and the time profile place it.
double froude_midpoint(const SphRun &run, const IntervalStats &iv, double steps) {
    return (iv.time_s - 0.5 * steps * run.config.dt) / std::sqrt(run.config.scale);
}

// Every (interval, rank) of a run with at least one step.
std::vector<Point> points_of(const SphRun &run, int index) {
    std::vector<Point> out;
    for (const auto &iv : run.intervals)
        for (const auto &r : iv.ranks) {
            if (r.steps < 1)
                continue;
            Point p;
            p.work = {r.field_mean, r.virtual_, r.ghost,           r.interactions,
                      r.cell_moves, r.descents, mean_round_trip(r)};
            p.pairs = r.pairs;
            p.exported = r.exported;
            p.compute_s_per_step = r.compute_s() / r.steps;
            p.froude_t = froude_midpoint(run, iv, r.steps);
            p.run = index;
            p.ranks = run.config.ranks;
            out.push_back(p);
        }
    return out;
}

// A single rank has no neighbour to export to: its zeros are not points of the export law
// (kept only when the calibration has nothing else).
std::vector<Point> exporting(const std::vector<Point> &pts) {
    std::vector<Point> out;
    std::copy_if(pts.begin(), pts.end(), std::back_inserter(out),
                 [](const Point &p) { return p.ranks > 1 && p.work.field > 0; });
    return out.size() >= 3 ? out : pts;
}

template <class Y> json regression(const std::vector<Point> &pts, Y y) {
    std::vector<double> n, v;
    for (const auto &p : pts)
        if (p.work.field > 0) { // the linear law is for ranks holding field particles
            n.push_back(p.work.field);
            v.push_back(y(p));
        }
    if (n.size() < 3)
        throw UsageError("the calibration runs give " + std::to_string(n.size()) +
                         " rank-intervals with field particles; the regressions need >= 3 "
                         "(use more ranks or shorter --interval)");
    try {
        return fit_line_mr(n, v).to_json();
    } catch (const std::invalid_argument &) {
        // Every rank held about the same n (a still tank cut evenly): the intercept cannot be
        // told from the slope, so the law is proportional, p = m n, and says so.
        std::vector<std::vector<double>> X;
        for (double x : n)
            X.push_back({x});
        json j = fit_linear(X, v, {"m"}).to_json();
        j["terms"] = {"m", "r"};
        j["coefficients"]["r"] = {{"value", 0.0}, {"se", 0.0}, {"se_pct", 0.0}};
        j["intercept_fixed_at_zero"] = true;
        return j;
    }
}

// A candidate set of cost terms that fits no negative cost, with its held-out scores.
struct Scored {
    std::vector<std::string> terms;
    CvScore score;
    json cv_run;
};

// The terms of the cost fit (select_term_set, fit.hpp). levelled_best (since session 64): the
// set with the lowest held-out error. levelled_one_se (sessions 13-63): the smallest set within
// one standard error of it; it dropped the per-step and per-particle costs the small calibration
// runs carry, and predicted the scale-1 dam breaks 3-8 % high over eight main jobs
// (model/NOTES.md, session 64). pooled_one_percent: each larger set has to lower the error by
// 1 %.
const Scored &select_terms(const std::vector<Scored> &ok, TermSelection rule) {
    std::vector<CvScore> scores;
    std::vector<std::size_t> sizes;
    for (const auto &c : ok) {
        scores.push_back(c.score);
        sizes.push_back(c.terms.size());
    }
    return ok[select_term_set(scores, sizes,
                              rule == TermSelection::levelled_best     ? TermRule::best
                              : rule == TermSelection::levelled_one_se ? TermRule::one_se
                                                                       : TermRule::one_percent)];
}

// Cost fit for one grid and thread count: every subset of terms containing "interactions" whose
// costs all come out non-negative is scored by leave-one-run-out cross-validation (with one
// cost level per setup unless the rule pools them); the rule picks one, every score is reported.
// With a Froude-time profile, the points of each setup up to the Froude time its shortest run
// reaches. The cost of an interaction rises 40 % over a dam break as the particles lose their
// memory order (the profile's part); a long small-scale run beside a short larger-scale one
// would otherwise pass that rise off as a per-particle cost of the wrong sign.
std::vector<Point> common_reach(const std::vector<Point> &pts, const std::vector<SphRun> &runs) {
    std::map<int, double> run_reach;
    for (const auto &p : pts)
        run_reach[p.run] = std::max(run_reach[p.run], p.froude_t);
    std::map<std::string, double> reach;
    for (const auto &[run, t] : run_reach) {
        const auto &setup = runs.at(static_cast<std::size_t>(run)).config.setup;
        const auto it = reach.find(setup);
        reach[setup] = it == reach.end() ? t : std::min(it->second, t);
    }
    std::vector<Point> out;
    for (const auto &p : pts)
        if (p.froude_t <= reach.at(runs.at(static_cast<std::size_t>(p.run)).config.setup))
            out.push_back(p);
    return out;
}

// A work term that names the setup rather than following the configuration: its value within
// each setup stays (nearly) put although the calibration changed a setup's scale or rank count.
// Its cost per unit is then a free number, fixed by the gap between the setups' levels (which
// the setup's level or "const" already carries), and any other count multiplies it. Session 32:
// every list calibration run held 16 ghosts per rank in the dam break and 136 in the still tank;
// the fit costed them at 6.9 us each, and a 3-rank run with 252-265 ghosts per water rank came
// out 34 % high. Session 33: the table runs' cell moves sat at 16 and 136-141 per rank and step
// (0.09 % of their variance within the setups); the fit costed them at 11 us each, and the
// 3- and 4-rank runs (about 260 per rank) came out 24-162 % high. Every other term in 14 jobs'
// calibration runs keeps at least 75 % of its variance within the setups. With one configuration
// per setup nothing tells a per-unit cost from a fixed one, and cross-validation decides as
// before (a 1-rank run at one scale holds its particles fixed; excluding "owned" there cost 48 %
// at twice the scale in one session-31 job).
struct SetupTerm {
    std::string term;
    double within_setup_variance_fraction;
};
// Below this share of its variance within the setups (a spread within each setup under a tenth
// of the spread over all points) a term names the setup. Tuned: chosen after session 33's job.
constexpr double max_within_setup_fraction = 0.01;

std::vector<SetupTerm> setup_terms(const std::vector<Point> &pts, const std::vector<SphRun> &runs,
                                   const std::vector<std::string> &terms) {
    std::map<std::string, std::set<std::pair<double, int>>> configs;
    for (const auto &p : pts) {
        const auto &c = runs.at(static_cast<std::size_t>(p.run)).config;
        configs[c.setup].insert({c.scale, c.ranks});
    }
    std::vector<SetupTerm> out;
    if (std::none_of(configs.begin(), configs.end(),
                     [](const auto &c) { return c.second.size() >= 2; }))
        return out;
    for (const auto &t : terms) {
        if (t == "const")
            continue;
        std::map<std::string, std::pair<double, int>> sum;
        double total = 0.0;
        for (const auto &p : pts) {
            const auto &setup = runs.at(static_cast<std::size_t>(p.run)).config.setup;
            auto &s = sum[setup];
            s.first += p.work.value(t);
            ++s.second;
            total += p.work.value(t);
        }
        const double mean = total / static_cast<double>(pts.size());
        double within = 0.0, all = 0.0;
        for (const auto &p : pts) {
            const auto &s = sum.at(runs.at(static_cast<std::size_t>(p.run)).config.setup);
            const double v = p.work.value(t);
            within += std::pow(v - s.first / s.second, 2);
            all += std::pow(v - mean, 2);
        }
        const double fraction = all > 0 ? within / all : 0.0;
        if (fraction < max_within_setup_fraction)
            out.push_back({t, fraction});
    }
    return out;
}

// A configuration's identity among calibration runs: repeats of it differ only by the machine.
std::string configuration_key(const RunConfig &c) {
    std::ostringstream k;
    k << c.setup << ' ' << c.grid << ' ' << c.scale << ' ' << c.delta << ' ' << c.dt << ' '
      << c.steps << ' ' << c.ranks << 'x' << c.threads << ' ' << c.decomposition << ' ' << c.overlap
      << ' ' << c.boundary;
    return k.str();
}

json compute_fit(const std::vector<Point> &all_pts, const std::vector<SphRun> &runs,
                 TermSelection rule, TimeProfile profile, FitWeights weights,
                 RunLevelRule level_rule, bool walls_term, bool bound_item_costs,
                 CvHoldOut hold_out) {
    const std::vector<Point> pts =
        profile != TimeProfile::none ? common_reach(all_pts, runs) : all_pts;
    // With a Froude-time profile the flow's evolution is the profile's: no term that grows with
    // simulated time (descents) competes with it. Not `walls` alone (every wall particle of the
    // rank): a rank's dry walls cost nothing measurable (session 51: a 2-rank Cell+Table dam
    // break at scale 0.35 against 1 rank, half the walls on the busy rank and the same
    // interactions, 1.008 +- 0.016 times its time, under 0.2 us per wall), while calibration at
    // two scales cannot tell it from `const` (tied scores) and it priced a wall at 2.7 us, which
    // put a 2-rank run 18 % under its 1-rank twin. A wet wall's pair work is in `interactions`.
    // calibrate --walls-term offers it again (sessions 1-50's candidates).
    std::vector<std::string> optional{"const", "owned", "ghost", "cell_moves"};
    if (walls_term)
        optional.insert(optional.begin() + 2, "walls");
    if (profile == TimeProfile::none)
        optional.push_back("descents");
    // The inter-core latency where every point measured it (runs of two or more threads): this
    // VM's vCPUs pass a cache line in about 60 or about 350 ns, switching in spells, and a step
    // of two threads waits on a number of round trips (barriers, lines the other core wrote)
    // whatever its work, so a run in the slow mode costs more per step, the smallest runs most
    // (model/NOTES.md, session 71). Fitted as a cost like the others, the mode no longer
    // passes for the level of the runs that ran in it.
    const bool round_trips =
        !pts.empty() && std::all_of(pts.begin(), pts.end(),
                                    [](const Point &p) { return p.work.core_round_trip_s > 0; });
    if (round_trips)
        optional.push_back("core_round_trips");
    const std::vector<SetupTerm> excluded = setup_terms(pts, runs, optional);
    std::erase_if(optional, [&](const std::string &t) {
        return std::any_of(excluded.begin(), excluded.end(),
                           [&](const SetupTerm &e) { return e.term == t; });
    });
    json candidates = json::array();
    std::vector<Scored> ok;
    std::vector<double> y;
    std::vector<int> groups, setups;
    std::map<std::string, int> setup_index;
    for (const auto &p : pts) {
        y.push_back(p.compute_s_per_step);
        groups.push_back(p.run);
        if (rule != TermSelection::pooled_one_percent) {
            const auto &setup = runs.at(static_cast<std::size_t>(p.run)).config.setup;
            setups.push_back(
                setup_index.emplace(setup, static_cast<int>(setup_index.size())).first->second);
        }
    }
    const bool by_run = std::set<int>(groups.begin(), groups.end()).size() >= 2;
    // The folds the term selection scores on: runs, or configurations where a setup has two or
    // more (a setup's only configuration held out would leave its level unfitted).
    std::vector<int> folds = groups;
    if (hold_out == CvHoldOut::configuration) {
        std::map<std::string, std::set<std::string>> setup_configs;
        for (const auto &p : pts) {
            const auto &c = runs.at(static_cast<std::size_t>(p.run)).config;
            setup_configs[c.setup].insert(configuration_key(c));
        }
        std::map<std::string, int> config_index;
        const int first = static_cast<int>(runs.size());
        for (std::size_t i = 0; i < pts.size(); ++i) {
            const auto &c = runs.at(static_cast<std::size_t>(pts[i].run)).config;
            if (setup_configs.at(c.setup).size() >= 2)
                folds[i] = config_index
                               .emplace(configuration_key(c),
                                        first + static_cast<int>(config_index.size()))
                               .first->second;
        }
    }
    // Relative weights: every row divided by its run's median step (a run's own scale, not the
    // point's noisy value), so the fit, its levels and its held-out error are per unit of step.
    // The held-out scores carry their unit: seconds per step, or a fraction of the run's step.
    const bool relative = weights == FitWeights::relative;
    const std::string cv_key = relative ? "cv_rmse_rel" : "cv_rmse_s",
                      cv_se_key = relative ? "cv_rmse_se_rel" : "cv_rmse_se_s";
    const std::vector<double> unit =
        relative ? group_median_units(y, groups) : std::vector<double>(pts.size(), 1.0);
    std::vector<double> yw = y;
    for (std::size_t i = 0; i < pts.size(); ++i)
        yw[i] /= unit[i];
    auto design = [&](const std::vector<std::string> &terms, bool weighted) {
        std::vector<std::vector<double>> X;
        for (const auto &p : pts) {
            X.emplace_back();
            for (const auto &t : terms)
                X.back().push_back(p.work.value(t));
        }
        return weighted ? divided_rows(std::move(X), unit) : X;
    };
    // A fluid particle's interactions per step (the median over the rank-intervals holding
    // fluid): what one item may cost at most, in units of the interactions' coefficient.
    std::vector<double> per_fluid;
    for (const auto &p : pts)
        if (p.work.field > 0)
            per_fluid.push_back(p.work.interactions / p.work.field);
    const double interactions_per_fluid = per_fluid.empty() ? 0.0 : median(per_fluid);
    for (unsigned mask = 0; mask < (1u << optional.size()); ++mask) {
        std::vector<std::string> terms{"interactions"};
        for (std::size_t k = 0; k < optional.size(); ++k)
            if (mask & (1u << k))
                terms.push_back(optional[k]);
        const std::vector<std::vector<double>> X = design(terms, true);
        try {
            const CvScore score = cross_validate_score(X, yw, folds, setups);
            // The held-out runs' summed-compute error, reported beside. Selecting on it was
            // tried in session 12 and not kept (model/NOTES.md, "Cost across scales").
            const json cv_run =
                by_run ? json(cross_validate_runs(X, yw, groups, setups)) : json(nullptr);
            json c = {{"terms", terms},
                      {cv_key, score.rmse},
                      {cv_se_key, score.rmse_se},
                      {"cv_run_rel_rms", cv_run}};
            // Every term is a cost: a set that fits one negative (one cost traded against
            // another, as ghosts against cell moves in two runs) is not a physical model.
            const LinearFit all = fit_levelled(X, yw, terms, setups).fit;
            // One item's cost against a fluid particle's interactions (terms[0]).
            const double particle = all.coef[0] * interactions_per_fluid;
            bool above = false;
            for (std::size_t k = 1; k < terms.size(); ++k)
                if (terms[k] == "owned" || terms[k] == "ghost" || terms[k] == "cell_moves" ||
                    terms[k] == "walls")
                    above = above || all.coef[k] > particle;
            if (std::any_of(all.coef.begin(), all.coef.end(), [](double v) { return v < 0; }))
                c["negative_cost"] = true;
            else if (bound_item_costs && above)
                c["item_above_a_particle"] = true;
            else
                ok.push_back({terms, score, cv_run});
            candidates.push_back(c);
        } catch (const std::invalid_argument &) {
            candidates.push_back({{"terms", terms}, {cv_key, nullptr}, {"rank_deficient", true}});
        }
    }
    if (ok.empty())
        throw UsageError("no cost model can be fitted to these calibration runs (too few "
                         "distinct rank-intervals)");
    const Scored &chosen = select_terms(ok, rule);
    const std::vector<std::string> &best = chosen.terms;
    const std::vector<std::vector<double>> X = design(best, false), Xw = design(best, true);
    // Least squares picks the shape (which terms, in what ratio); the level is the median
    // calibration run's, and per setup the rule's (below). Where a time profile is fitted, a
    // pooled profile carries the runs' pooled level and overrides it (--run-level pooled, and
    // setups without repeats); a shape-only one leaves it (compute_time_profile).
    const LinearFit ls = fit_levelled(Xw, yw, best, setups).fit;
    const RunLevel level = run_level(ls, Xw, yw, groups);
    const LinearFit f = scaled(ls, level.median);
    // The level per setup too: the cost of an interaction depends on the flow (measured here,
    // the still tank's runs sit 5-15 % below the dam break's on the stored-list grids, in every
    // main job), and a prediction is always of one setup.
    // With fastest_repeat, repeats of one configuration give the fastest: on this VM a slow
    // spell of the host only adds time, and it hit one or two of a configuration's three short
    // runs in 8 of 23 main jobs (model/NOTES.md, session 43).
    std::map<std::string, std::vector<double>> setup_factors;
    std::map<std::string, std::map<std::string, std::vector<double>>> repeats;
    for (std::size_t k = 0; k < level.groups.size(); ++k) {
        const RunConfig &c = runs.at(static_cast<std::size_t>(level.groups[k])).config;
        setup_factors[c.setup].push_back(level.factors[k]);
        repeats[c.setup][configuration_key(c)].push_back(level.factors[k]);
    }
    json per_setup = json::object();
    for (const auto &[setup, v] : setup_factors) {
        const double median = sphperf::median(v), fastest = fastest_repeat_level(repeats.at(setup));
        per_setup[setup] = {
            {"factor", level_rule == RunLevelRule::fastest_repeat ? fastest : median},
            {"factor_median", median},
            {"factor_fastest_repeat", fastest},
            {"factor_mean", sphperf::summarize(v).avg},
            {"runs", v.size()},
            {"configurations", repeats.at(setup).size()}};
    }
    std::vector<double> residuals;
    double ss_res = 0, ss_tot = 0;
    const double y_mean = std::accumulate(y.begin(), y.end(), 0.0) / static_cast<double>(y.size());
    for (std::size_t i = 0; i < pts.size(); ++i) {
        residuals.push_back(f.predict(X[i]) - y[i]);
        ss_res += residuals.back() * residuals.back();
        ss_tot += (y[i] - y_mean) * (y[i] - y_mean);
    }
    json j = f.to_json();
    // R^2 and the residual standard error in seconds per step whatever the weights (a
    // relative fit's own are per unit of step).
    const double dof = static_cast<double>(pts.size() - best.size());
    j["r2"] = ss_tot > 0 ? 1.0 - ss_res / ss_tot : 1.0;
    j["rse"] = dof > 0 ? std::sqrt(ss_res / dof) : 0.0;
    j["fit_weights"] = relative ? "relative" : "absolute";
    j["cv_hold_out"] = hold_out == CvHoldOut::configuration ? "configuration" : "run";
    json factors = json::array();
    for (std::size_t k = 0; k < level.groups.size(); ++k)
        factors.push_back({{"run", runs.at(static_cast<std::size_t>(level.groups[k])).path},
                           {"factor", level.factors[k]}});
    j["least_squares"] = ls.to_json();
    j["run_level"] = {{"method", "median over calibration runs of measured / least-squares "
                                 "compute time; the coefficients are scaled by it"},
                      {"factor", level.median},
                      {"factor_mean", level.mean},
                      {"uses", level_rule == RunLevelRule::fastest_repeat
                                   ? "per setup: the fastest repeat of each configuration, the "
                                     "median over configurations (per_setup.factor)"
                                   : "median"},
                      {"rule", level_rule == RunLevelRule::fastest_repeat ? "fastest-repeat"
                               : level_rule == RunLevelRule::median       ? "median"
                                                                          : "pooled"},
                      {"spread_pct", level.spread_pct},
                      {"runs", factors},
                      {"per_setup", per_setup},
                      {"scatter", scatter_json(level_scatter(setup_factors))}};
    j[cv_key] = chosen.score.rmse;
    j[cv_se_key] = chosen.score.rmse_se;
    j["cv_run_rel_rms"] = chosen.cv_run;
    j["selected_by"] =
        rule == TermSelection::levelled_one_se
            ? "levelled-one-se: one cost level per setup in the fit and its leave-one-run-out "
              "cross-validation; the smallest set of terms whose held-out root mean square "
              "error per step is within one standard error (cv_rmse_se_s, or cv_rmse_se_rel "
              "with relative weights) of the best set's"
        : rule == TermSelection::levelled_best
            ? "levelled-best: one cost level per setup in the fit and its leave-one-run-out "
              "cross-validation; the set of terms with the lowest held-out root mean square "
              "error per step"
            : "pooled-one-percent: one fit pooling the setups; a larger set of terms kept when "
              "it lowers the held-out root mean square error per step by 1 %";
    j["term_selection"] = rule == TermSelection::levelled_one_se ? "levelled-one-se"
                          : rule == TermSelection::levelled_best ? "levelled-best"
                                                                 : "pooled-one-percent";
    j["candidates"] = candidates;
    j["item_cost_bound"] = bound_item_costs ? "particle" : "none";
    j["interactions_per_fluid_particle"] = interactions_per_fluid;
    json ex = json::array();
    for (const auto &e : excluded)
        ex.push_back({{"term", e.term},
                      {"within_setup_variance_fraction", e.within_setup_variance_fraction},
                      {"max_within_setup_fraction", max_within_setup_fraction},
                      {"reason", "(nearly) one value per setup over the fit's points although "
                                 "a setup ran in two configurations: it names the setup, not a "
                                 "cost per unit"}});
    j["excluded_terms"] = ex;
    if (round_trips) {
        // What a prediction puts in for the term: the mean over the fit's rank-intervals, what
        // a sum of steps pays over the modes in their calibration shares; the median (the
        // usual mode) and the spread beside.
        std::vector<double> rt;
        for (const auto &p : pts)
            rt.push_back(p.work.core_round_trip_s);
        const Summary s = summarize(rt);
        j["core_round_trip_s"] = {
            {"mean", s.avg},
            {"median", s.median},
            {"min", s.min},
            {"max", s.max},
            {"far_fraction", static_cast<double>(std::count_if(
                                 rt.begin(), rt.end(),
                                 [](double v) { return v > SphRun::far_core_round_trip_s; })) /
                                 static_cast<double>(rt.size())},
            {"points", rt.size()},
            {"prediction_uses", "mean"}};
    }
    j["residuals_s"] = residuals;
    j["runs"] = std::set<int>(groups.begin(), groups.end()).size();
    j["fit_window"] = {{"points_used", pts.size()},
                       {"points_recorded", all_pts.size()},
                       {"rule", profile != TimeProfile::none
                                    ? "per setup, intervals up to the Froude time its shortest "
                                      "calibration run reaches"
                                    : "every interval"}};
    return j;
}

// Cell moves per step from the work the model knows in advance (field, walls, ghosts): the
// largest of these sets the runs can tell apart (a single 2-rank run whose water stays on one
// rank has two distinct rows only), down to a constant.
json cell_move_fit(const std::vector<Point> &pts) {
    const std::vector<std::vector<std::string>> sets{{"field", "walls", "ghost", "const"},
                                                     {"field", "walls", "const"},
                                                     {"field", "const"},
                                                     {"const"}};
    std::vector<double> y;
    for (const auto &p : pts)
        y.push_back(p.work.cell_moves);
    for (const auto &terms : sets) {
        std::vector<std::vector<double>> X;
        for (const auto &p : pts) {
            X.emplace_back();
            for (const auto &t : terms)
                X.back().push_back(t == "field"   ? p.work.field
                                   : t == "walls" ? p.work.walls
                                   : t == "ghost" ? p.work.ghost
                                                  : 1.0);
        }
        try {
            return fit_linear(X, y, terms).to_json();
        } catch (const std::invalid_argument &) {
            if (terms.size() == 1)
                throw;
        }
    }
    throw std::logic_error("cell_move_fit: unreachable");
}

// Per setup and grid (each grid visits candidates in its own order), the memory-order decay of
// the stored-list runs reaching furthest in simulated time (the mean of those with the same
// record times: rounds of the same configuration).
json disorder_by_setup(const std::vector<SphRun> &runs, OrderLineGauge gauge) {
    std::map<std::pair<std::string, std::string>, std::vector<SphRun>> longest;
    auto end_of = [](const SphRun &r) { return r.intervals.back().time_s; };
    // Runs of one configuration on two grids: the same scale, spacing, ranks, slabs, columns
    // and record times.
    auto same_record = [&](const SphRun &a, const SphRun &b) {
        return a.config.scale == b.config.scale && a.config.delta == b.config.delta &&
               a.config.ranks == b.config.ranks && a.config.decomposition == "equal" &&
               b.config.decomposition == "equal" && a.intervals.size() == b.intervals.size() &&
               std::abs(end_of(a) - end_of(b)) <= 1e-9 * end_of(a) &&
               a.intervals.front().column_interactions.size() ==
                   b.intervals.front().column_interactions.size();
    };
    for (const auto &r : runs) {
        if (r.config.grid != "list" && r.config.grid != "table")
            continue;
        auto &v = longest[{r.config.setup, r.config.grid}];
        if (!v.empty() && end_of(r) > end_of(v.front()) * (1 + 1e-9))
            v.clear();
        if (v.empty() || (r.intervals.size() == v.front().intervals.size() &&
                          std::abs(end_of(r) - end_of(v.front())) <= 1e-9 * end_of(r) &&
                          r.config.delta == v.front().config.delta))
            v.push_back(r);
    }
    // The runs as the line is first fitted, and as it is fitted again where that line is
    // unusable (interval-or-kernel: a noisy spell flattened round a's one long Cell+Table run
    // in three of session 93's four blind jobs).
    const bool by_interval =
        gauge == OrderLineGauge::interval || gauge == OrderLineGauge::interval_or_kernel;
    auto first_gauged = [&](const std::vector<SphRun> &v) {
        return by_interval                       ? within_run_speed(v, speed_gauge_half_window)
               : gauge == OrderLineGauge::kernel ? within_run_kernel_speed(v)
                                                 : v;
    };
    const bool kernel_fallback = gauge == OrderLineGauge::interval_or_kernel;
    const std::map<std::pair<std::string, std::string>, std::vector<SphRun>> raw = longest;
    for (auto &[key, v] : longest)
        v = first_gauged(v);
    // The line of `v` (times as first gauged; `v_raw` as measured) with `order` standing for
    // its descents where given, refitted on the kernel-gauged times where it is unusable.
    auto line_of = [&](const std::vector<SphRun> &v, const std::vector<SphRun> &v_raw,
                       const std::vector<SphRun> &order) {
        std::optional<ColumnDisorder> line = column_disorder_of(v, order);
        if (kernel_fallback && (!line || !line->unusable().empty())) {
            std::optional<ColumnDisorder> again =
                column_disorder_of(within_run_kernel_speed(v_raw), order);
            if (again && again->unusable().empty()) {
                again->gauge_note = "the interval gauge's line was unusable (" +
                                    (line ? line->unusable() : std::string("no line")) +
                                    "): fitted on the kernel-gauged times";
                return again;
            }
        }
        return line;
    };
    json out = json::object();
    for (const auto &[key, v] : longest) {
        json d = disorder_of(v).to_json();
        d["method"] = "descents per interaction summed over ranks, mean of the runs; predict "
                      "reads it at the target's simulated time (acoustic time for another "
                      "spacing), not at its Froude time";
        // Per column too (reports since session 56): predict gives each rank the memory order
        // of its own columns.
        constexpr std::string_view interval_gauge =
            " (each interval's times over its speed gauge against the run's whole, calibrate "
            "--order-line-gauge interval)";
        constexpr std::string_view kernel_gauge =
            " (each rank-interval's times over its kernel's time per interaction against the "
            "run's median, calibrate --order-line-gauge kernel)";
        // The method names the gauge the kept line was fitted on: a line the kernel fallback
        // fitted again carries its note.
        auto method_of = [&](const ColumnDisorder &c) {
            const std::string_view how_gauged = !c.gauge_note.empty() ? kernel_gauge
                                                : by_interval         ? interval_gauge
                                                : gauge == OrderLineGauge::kernel
                                                    ? kernel_gauge
                                                    : std::string_view{};
            return "interactions and descents per cell column, mean of the runs, read by "
                   "predict at the target's simulated time (--memory-order-time columns) or "
                   "Froude time, the columns at their relative place; compute per interaction "
                   "= intercept + slope x descents per interaction, fitted (one level per run) "
                   "on the rank-intervals holding at least a tenth of the interactions in the "
                   "later half of each run" +
                   std::string(how_gauged) +
                   "; predict multiplies each rank's compute by (intercept + slope D_rank) / "
                   "(intercept + slope D_all), D of the rank's columns and of all of them";
        };
        auto keep = [&](const ColumnDisorder &c, const char *usable_key, const char *unused_key,
                        std::string_view more) {
            const std::string why_not = c.unusable();
            const char *k = why_not.empty() ? usable_key : unused_key;
            d[k] = c.to_json();
            if (!why_not.empty())
                d[k]["unused_because"] = why_not;
            d[k]["method"] = method_of(c) + std::string(more);
            return why_not.empty();
        };
        bool usable = false;
        if (const auto by_column = line_of(v, raw.at(key), {}))
            usable = keep(*by_column, "by_column", "by_column_unused", "");
        // Cell+List's descents do not see its memory order; Cell+Table's runs of the same
        // configuration (the same particles, the same migrations) do (workload.hpp), where
        // their own cost line is usable (not a still tank's, whose order barely moves).
        auto table_line_usable = [&](const std::vector<SphRun> &t) {
            const auto own = line_of(t, raw.at({key.first, "table"}), {});
            return own && own->unusable().empty();
        };
        if (const auto table = longest.find({key.first, "table"});
            !usable && key.second == "list" && table != longest.end() &&
            same_record(v.front(), table->second.front()) && table_line_usable(table->second)) {
            std::optional<ColumnDisorder> by_table;
            try {
                by_table = line_of(v, raw.at(key), table->second);
            } catch (const std::invalid_argument &) {
                // Record times that differ inside the run: no line read across them.
            }
            if (by_table)
                keep(*by_table, "by_column", "by_column_table_order_unused",
                     "; the descents are Cell+Table's runs' (descents_from) in the "
                     "same columns at the same times, read over each Cell+List rank's "
                     "equal slab: Cell+List's own stay at 0.86 per interaction "
                     "whatever its memory order");
        }
        out[key.first][key.second] = d;
    }
    return out;
}

json roofline(const json &machine, const std::vector<SphRun> &runs) {
    struct Totals {
        double flops = 0, bytes = 0;
        json stages = json::array();
    };
    auto totals = [](std::span<const InteractionCost> costs) {
        Totals t;
        for (const auto &c : costs) {
            t.flops += c.flops;
            t.bytes += c.bytes;
            t.stages.push_back({{"stage", c.stage}, {"flops", c.flops}, {"bytes", c.bytes}});
        }
        return t;
    };
    // The stored-list grids (list, table) at the top level, every scheme under "schemes".
    const Totals stored = totals(interaction_costs);
    const double flops = stored.flops, bytes = stored.bytes;
    const json stages = stored.stages;
    json schemes = json::object();
    for (const char *grid : {"list", "table", "sorted"}) {
        const Totals t = totals(interaction_costs_of(grid));
        schemes[grid] = {{"flops_per_interaction", t.flops},
                         {"bytes_per_interaction", t.bytes},
                         {"operational_intensity_flop_per_byte", t.flops / t.bytes},
                         {"stages", t.stages}};
    }
    const double peak = machine.at("peak_gflops").get<double>();
    const double per_core = machine.value("peak_gflops_per_core", peak);
    const double triad = machine.at("stream_triad_GBps").get<double>();
    const double dgemm = machine.value("dgemm_gflops", 0.0);
    const double intensity = flops / bytes;
    json points = json::array();
    for (const auto &r : runs) {
        double interactions = 0;
        for (const auto &iv : r.intervals)
            for (const auto &rk : iv.ranks)
                interactions += rk.interactions * rk.steps;
        // Achieved rates over the run's wall time on all its ranks, by its own scheme's counts.
        const Totals own = totals(interaction_costs_of(r.config.grid));
        const double gflops = r.wall_s > 0 ? interactions * own.flops / r.wall_s * 1e-9 : 0.0;
        const double gbps = r.wall_s > 0 ? interactions * own.bytes / r.wall_s * 1e-9 : 0.0;
        const int cores =
            std::min(r.config.ranks * r.config.threads, machine.at("topology").value("cores", 1));
        points.push_back({{"run", r.path},
                          {"grid", r.config.grid},
                          {"ranks", r.config.ranks},
                          {"threads", r.config.threads},
                          {"operational_intensity_flop_per_byte", own.flops / own.bytes},
                          {"achieved_gflops", gflops},
                          {"achieved_GBps", gbps},
                          {"fraction_of_peak", gflops / std::min(peak, per_core * cores)},
                          {"fraction_of_triad", gbps / triad}});
    }
    const double ridge = peak / triad;
    double flop_fraction = 0, byte_fraction = 0;
    for (const auto &p : points) {
        flop_fraction = std::max(flop_fraction, p["fraction_of_peak"].get<double>());
        byte_fraction = std::max(byte_fraction, p["fraction_of_triad"].get<double>());
    }
    auto pct = [](double f) { return std::to_string(static_cast<int>(std::round(100 * f))) + "%"; };
    std::string verdict;
    if (flop_fraction >= 0.5)
        verdict = "compute bound";
    else if (byte_fraction >= 0.5)
        // The byte counts assume no reuse. Cell+Sorted reads each column range for every
        // particle of a cell, from cache: the no-reuse figure overstates memory traffic most.
        verdict = "neither: counted without reuse, the bytes would reach " + pct(byte_fraction) +
                  " of the triad, but every candidate range is read by all the particles of a "
                  "cell from cache (a rank's working set of a few MB stays in L2/L3), and the "
                  "flops reach at most " +
                  pct(flop_fraction) +
                  " of the FMA peak: the time goes to the latency and throughput of the "
                  "arithmetic (sqrt, division) and to packing the in-range candidates";
    else
        verdict = "neither: the SPH kernel reaches at most " +
                  pct(std::max(flop_fraction, byte_fraction)) +
                  " of either ceiling; with its no-reuse intensity below the ridge it would be "
                  "memory bound by the roofline, but its working set stays in cache and its "
                  "time goes to instruction latency (branches, sqrt, gathers)";
    return {{"flops_per_interaction", flops},
            {"bytes_per_interaction", bytes},
            {"operational_intensity_flop_per_byte", intensity},
            {"thesis_flops_per_pair", 89},
            {"thesis_bytes_per_pair", 56},
            {"stages", stages},
            {"schemes", schemes},
            {"ceilings",
             {{"peak_gflops", peak},
              {"peak_gflops_per_core", per_core},
              {"dgemm_gflops", dgemm},
              {"stream_triad_GBps", triad},
              {"ridge_flop_per_byte", ridge}}},
            {"runs", points},
            {"verdict", verdict}};
}

// Peak RSS per rank = fixed + bytes per stored particle x particles + bytes per interaction x
// interactions, the last two counted from our data structures (model/NOTES.md), the fixed part
// (MPI, OpenMP and libraries) the median residual of the calibration runs.
json memory_model(const std::vector<SphRun> &runs) {
    std::vector<double> fixed;
    for (const auto &r : runs)
        for (std::size_t k = 0; k < r.peak_rss_bytes.size(); ++k) {
            const MemoryCounts mc = memory_counts(r.config.grid);
            double particles = 0, interactions = 0;
            for (const auto &iv : r.intervals) {
                const auto &rk = iv.ranks[k];
                particles = std::max(particles, rk.field + rk.virtual_ + rk.ghost);
                interactions = std::max(interactions, rk.interactions);
            }
            fixed.push_back(r.peak_rss_bytes[k] - mc.per_particle * particles -
                            mc.per_interaction * interactions);
        }
    std::sort(fixed.begin(), fixed.end());
    json grids = json::object();
    for (const char *g : {"list", "table", "sorted"}) {
        const MemoryCounts mc = memory_counts(g);
        grids[g] = {{"bytes_per_particle", mc.per_particle},
                    {"bytes_per_interaction", mc.per_interaction}};
    }
    return {{"bytes_per_particle", bytes_per_particle},
            {"bytes_per_interaction", bytes_per_interaction},
            {"grids", grids},
            {"fixed_bytes", fixed.empty() ? 0.0 : fixed[fixed.size() / 2]}};
}
// Above the core count ranks take turns, and a core serving two busy ranks costs a little more
// than their summed compute (switches, a rank waiting for a descheduled neighbour). Measured on
// the app itself, per load (ranks x threads / cores): over the intervals where some core serves
// two or more busy ranks (where the run placed them, `placement_pus`; spread evenly when
// unbound), the measured interval time (the longest rank's timers: every step ends in a
// blocking exchange) over the busiest core's summed compute, each rank's compute predicted by
// the fit (the fit's level, not the run's time-shared timers). The model adds the difference per
// step (overhead_s_per_step): the switches happen at the step's exchanges, whatever its compute.
// The ratio (overhead) is kept beside: taken from the 1 ms steps of the sorted still tank, it
// put the 18 ms steps of the table still tank 2-16 % high in 13 of 14 main jobs (session 34).
// Where a load's runs differ at least 2x in step length (the shared core's summed compute per
// step), the overhead per step is also fitted as a + b x that compute (overhead_fit; session
// 36): at 2 processes per core the 8.7 ms steps of the balanced table dam break paid about
// 1.1 ms each, the 1 ms steps of the half-scale sorted still tank 0.2-0.3 ms. Predict uses
// the line only when asked (--time-sharing-overhead line): in two blind main jobs it did worse
// than the median (session 37).
json time_sharing(const std::vector<SphRun> &runs, const json &compute, int cores) {
    struct Shared {
        std::string run;
        double factor, seconds_per_step, compute_per_step;
    };
    std::map<double, std::vector<Shared>> by_load;
    for (const auto &r : runs) {
        if (!time_shared(r, cores))
            continue;
        const json *entry = compute_entry(compute, r);
        if (!entry)
            continue;
        const LinearFit f = compute_cost_of(*entry, r.config.setup);
        double bound = 0, measured = 0, shared_steps = 0;
        for (const auto &iv : r.intervals) {
            double steps = 0, longest = 0;
            const std::vector<double> fitted = fitted_compute(f, iv);
            std::vector<double> field;
            for (const auto &rk : iv.ranks) {
                field.push_back(rk.field_mean);
                steps = std::max(steps, rk.steps);
                double timers = 0;
                for (const auto &[name, v] : rk.timers)
                    timers += v;
                longest = std::max(longest, timers);
            }
            const SharedStep s =
                time_shared_step(fitted, field, r.placement_pus, r.config.threads, cores);
            if (s.shared_core) {
                bound += steps * s.step_s;
                measured += longest;
                shared_steps += steps;
            }
        }
        if (bound > 0)
            by_load[static_cast<double>(r.config.ranks * r.config.threads) / cores].push_back(
                {r.path, measured / bound, (measured - bound) / shared_steps,
                 bound / shared_steps});
    }
    json out = json::array();
    for (const auto &[load, v] : by_load) {
        std::vector<double> o, add, base;
        json per_run = json::array();
        for (const auto &x : v) {
            o.push_back(x.factor);
            add.push_back(x.seconds_per_step);
            base.push_back(x.compute_per_step);
            per_run.push_back({{"run", x.run},
                               {"overhead", x.factor},
                               {"overhead_s_per_step", x.seconds_per_step},
                               {"shared_compute_s_per_step", x.compute_per_step}});
        }
        const Summary s = sphperf::summarize(o), a = sphperf::summarize(add);
        const std::optional<LinearFit> line = fit_sharing_overhead(base, add);
        // Significant where the runs show the growth: a slope of at least two standard errors.
        // Only predict --time-sharing-overhead line uses it (session 37).
        const bool fit = line && line->coef[1] > 2 * line->se[1];
        // A sum of times pays the mean; the bimodal runs (a busy rank that shares its core with a
        // polling one, or not) make the median and the mean differ, so both are kept.
        json overhead_fit = nullptr;
        if (line) {
            const auto [lo, hi] = std::minmax_element(base.begin(), base.end());
            overhead_fit = {{"intercept_s_per_step", line->coef[0]},
                            {"intercept_se_s_per_step", line->se[0]},
                            {"per_compute", line->coef[1]},
                            {"per_compute_se", line->se[1]},
                            {"r2", line->r2},
                            {"runs", v.size()},
                            {"shared_compute_s_per_step_min", *lo},
                            {"shared_compute_s_per_step_max", *hi},
                            {"significant", fit}};
        }
        out.push_back({{"load", load},
                       {"overhead", s.median},
                       {"overhead_mean", s.avg},
                       {"overhead_min", s.min},
                       {"overhead_max", s.max},
                       {"overhead_s_per_step", a.median},
                       {"overhead_s_per_step_mean", a.avg},
                       {"overhead_s_per_step_min", a.min},
                       {"overhead_s_per_step_max", a.max},
                       {"overhead_fit", overhead_fit},
                       {"uses", fit ? "median of overhead_s_per_step (predict "
                                      "--time-sharing-overhead line: overhead_fit, intercept + "
                                      "per_compute x the shared core's summed compute per step)"
                                    : "median of overhead_s_per_step"},
                       {"runs", per_run},
                       {"method", "over the intervals where a core serves two or more busy "
                                  "ranks, measured time against the busiest core's summed "
                                  "predicted compute (ranks where the run placed them): "
                                  "overhead, their ratio; overhead_s_per_step, their difference "
                                  "per step; medians over the time-shared calibration runs at "
                                  "this load"}});
    }
    return out;
}
// Step-to-step jitter, from the runs within the cores whose ranks all hold field particles:
// the k of a rank's compute noise per step (jitter.hpp) for which the model's wait (every step
// lasts the expected maximum of the ranks' compute + communication) equals the measured wait.
// Each rank's compute is the fitted one at the run's own level (measured over fitted), so k also
// covers imbalance the model cannot foresee (two cores at different speeds), and the
// communication is the measured one (validated apart). Both forms are fitted; the model uses
// `form`, or where it is not given the one whose leave-one-run-out prediction of the runs'
// waits is closer (the runs' steps differ by grid: Cell+Sorted's are a third of the others').
json jitter(const std::vector<SphRun> &runs, const json &compute, int cores,
            std::optional<JitterForm> form) {
    constexpr std::array forms{JitterForm::sqrt, JitterForm::proportional};
    json per_run = json::array();
    std::vector<WaitRun> wait_runs;
    std::map<JitterForm, std::vector<double>> ks;
    for (const auto &r : runs) {
        const json *entry = compute_entry(compute, r);
        if (time_shared(r, cores) || r.config.ranks < 2 || !entry)
            continue;
        const LinearFit f = compute_cost_of(*entry, r.config.setup);
        WaitRun w;
        double measured_compute = 0, fitted_sum = 0, steps = 0;
        for (const auto &iv : r.intervals) {
            const bool all_busy = std::all_of(iv.ranks.begin(), iv.ranks.end(), [](const auto &k) {
                return k.field_mean > 0 && k.steps >= 1;
            });
            if (!all_busy)
                continue;
            BusyInterval b{iv.ranks.front().steps, fitted_compute(f, iv), {}};
            for (const auto &rk : iv.ranks) {
                b.comm_s.push_back(rk.timer("comm_s") / rk.steps);
                measured_compute += rk.compute_s();
                w.measured_wait_s += rk.timer("wait_s");
                w.measured_time_s += rk.compute_s() + rk.timer("comm_s") + rk.timer("wait_s");
            }
            for (double c : b.compute_s)
                fitted_sum += c * b.steps;
            steps += b.steps;
            w.busy.push_back(std::move(b));
        }
        if (w.busy.empty() || !(fitted_sum > 0) || !(w.measured_time_s > 0))
            continue;
        // The fitted compute at this run's own level: k is jitter, not the machine's drift.
        for (auto &b : w.busy)
            for (auto &c : b.compute_s)
                c *= measured_compute / fitted_sum;
        const double mean_compute =
            measured_compute / (steps * static_cast<double>(r.config.ranks));
        json entry_k = json::object();
        for (JitterForm fm : forms) {
            const double k = fit_jitter(w.busy, w.measured_wait_s, fm);
            ks[fm].push_back(k);
            entry_k[std::string(to_string(fm))] = k;
        }
        // Either form's deviation at the run's own mean step: the same figure.
        const double relative =
            jitter_sd(Jitter{JitterForm::proportional, entry_k.at("proportional").get<double>()},
                      mean_compute) /
            mean_compute;
        per_run.push_back(
            {{"run", r.path},
             {"k_sqrt_s", entry_k.at("sqrt")},
             {"k_proportional", entry_k.at("proportional")},
             {"at_bound", entry_k.at("sqrt").get<double>() >= jitter_k_max ||
                              entry_k.at("proportional").get<double>() >= jitter_k_max},
             {"compute_per_step_s", mean_compute},
             {"relative_sd_at_run", relative},
             {"measured_wait_s", w.measured_wait_s},
             {"modelled_wait_without_jitter_s", modelled_wait(w.busy, Jitter{})},
             {"busy_steps", steps}});
        wait_runs.push_back(std::move(w));
    }
    if (wait_runs.empty())
        return nullptr;
    json cv = json::object();
    std::map<JitterForm, double> score;
    for (JitterForm fm : forms) {
        score[fm] = jitter_cv_rms(wait_runs, ks[fm], fm);
        cv[std::string(to_string(fm))] = std::isfinite(score[fm]) ? json(score[fm]) : json(nullptr);
    }
    // Without a score (fewer than 3 runs) the square root, sessions 15-60's form.
    const JitterForm chosen = form ? *form
                              : std::isfinite(score[JitterForm::proportional]) &&
                                      score[JitterForm::proportional] < score[JitterForm::sqrt]
                                  ? JitterForm::proportional
                                  : JitterForm::sqrt;
    const Summary sq = sphperf::summarize(ks[JitterForm::sqrt]);
    const Summary pr = sphperf::summarize(ks[JitterForm::proportional]);
    return {{"form", to_string(chosen)},
            {"form_chosen_by", form ? "option (calibrate --jitter-form)"
                               : std::isfinite(score[JitterForm::sqrt])
                                   ? "leave-one-run-out: the form whose prediction of each "
                                     "run's wait from the other runs' median k is closer (root "
                                     "mean square of the error over the run's time)"
                                   : "fewer than 3 runs to cross-validate: the square root"},
            {"cv_rms_wait_over_time", cv},
            {"k_sqrt_s", sq.median},
            {"k_mean_sqrt_s", sq.avg},
            {"k_min_sqrt_s", sq.min},
            {"k_max_sqrt_s", sq.max},
            {"k_proportional", pr.median},
            {"k_mean_proportional", pr.avg},
            {"k_min_proportional", pr.min},
            {"k_max_proportional", pr.max},
            {"uses", "median"},
            {"forms",
             {{"sqrt", "standard deviation of a rank's compute per step = k sqrt(compute_s), "
                       "k in s^0.5 (k_sqrt_s)"},
              {"proportional", "standard deviation of a rank's compute per step = k "
                               "compute_s, k a fraction (k_proportional)"}}},
            {"runs", per_run},
            {"method", "per run within the cores with every rank busy: the k for which the "
                       "expected maximum over ranks reproduces the measured wait, in each form; "
                       "the median over runs of the chosen form's"}};
}
} // namespace

// Per setup, measured over fitted compute of the busy ranks through the calibration runs of one
// grid and thread count, against Froude time (interval midpoint / sqrt(scale)): how the cost of
// the fitted work changes as the flow evolves. Measured at half scale, the cost of a dam-break
// interaction follows the flow's Froude time, not its simulated time (model/NOTES.md, "Cost
// over Froude time"). Each point is the ratio of sums over a window of neighbouring intervals
// (all runs pooled, sorted by time), so one noisy interval does not set it. With `smooth`
// (--time-profile froude, since session 42) the profile is a quadratic in Froude time fitted
// robustly to the pooled intervals' ratios: across main jobs its shape repeats within a few
// per cent (the table dam break's rises from 0.95 to 1.42 over 0.15 s of Froude time, the
// memory order decaying), while a slow spell of the host in one calibration run put a 10-20 %
// bump into the window's profile just where a scale-2 prediction reads all of its steps
// (model/NOTES.md, session 42). The windowed profile stays beside it (`factor_windowed`).
json compute_time_profile(const json &entry, const std::vector<const SphRun *> &runs, bool smooth,
                          bool shape_only) {
    constexpr int half_window = 2;          // intervals each side, per run
    constexpr std::size_t min_smoothed = 8; // fewer pooled intervals: the window alone
    json out = json::object();
    std::map<std::string, std::vector<const SphRun *>> by_setup;
    for (const SphRun *r : runs)
        by_setup[r->config.setup].push_back(r);
    // Each run's own level over its setup's (shape_only), from the fit's run factors.
    std::map<std::string, double> own_level;
    if (shape_only && entry.at("run_level").contains("runs"))
        for (const auto &r : entry.at("run_level").at("runs"))
            own_level[r.at("run").get<std::string>()] = r.at("factor").get<double>();
    for (const auto &[setup, rs] : by_setup) {
        const LinearFit f = compute_cost_of(entry, setup);
        const auto *per_setup = setup_level_of(entry, setup);
        const double setup_level = per_setup ? per_setup->at("factor").get<double>()
                                             : entry.at("run_level").at("factor").get<double>();
        // Only where a configuration was repeated: without repeats there is no faster run to
        // choose, and the pooled profile predicted the stored-list grids better (session 43).
        const bool repeated =
            per_setup && per_setup->value("configurations", 0) < per_setup->value("runs", 0);
        struct Sample {
            double t, measured, fitted;
        };
        std::vector<Sample> v;
        for (const SphRun *r : rs) {
            const auto own = own_level.find(r->path);
            const double at_own =
                !repeated || own == own_level.end() ? 1.0 : own->second / setup_level;
            for (const auto &iv : r->intervals) {
                const auto fit = fitted_compute(f, iv);
                Sample s{0, 0, 0};
                double steps = 0;
                for (std::size_t k = 0; k < iv.ranks.size(); ++k) {
                    const auto &rk = iv.ranks[k];
                    if (rk.steps < 1 || rk.field_mean <= 0)
                        continue;
                    steps = rk.steps;
                    s.measured += rk.compute_s();
                    s.fitted += fit[k] * rk.steps * at_own;
                }
                if (s.fitted <= 0)
                    continue;
                s.t = froude_midpoint(*r, iv, steps);
                v.push_back(s);
            }
        }
        if (v.empty())
            continue;
        std::sort(v.begin(), v.end(), [](const Sample &a, const Sample &b) { return a.t < b.t; });
        // Rounds of one configuration share their interval times: one point each, pooled.
        std::vector<Sample> merged;
        for (const auto &x : v)
            if (!merged.empty() && std::abs(x.t - merged.back().t) <= 1e-9 * std::abs(x.t)) {
                merged.back().measured += x.measured;
                merged.back().fitted += x.fitted;
            } else {
                merged.push_back(x);
            }
        v = std::move(merged);
        std::size_t longest = 1;
        for (const SphRun *r : rs)
            longest = std::max(longest, r->intervals.size());
        const auto n = static_cast<long>(v.size());
        // +-2 intervals of a run, whatever number of runs with other times interleave.
        const long w =
            half_window *
            std::max(1L, std::lround(static_cast<double>(n) / static_cast<double>(longest)));
        json times = json::array(), windowed = json::array();
        for (long i = 0; i < n; ++i) {
            double m = 0, fit = 0;
            for (long k = std::max(0L, i - w); k <= std::min(n - 1, i + w); ++k) {
                m += v[static_cast<std::size_t>(k)].measured;
                fit += v[static_cast<std::size_t>(k)].fitted;
            }
            times.push_back(v[static_cast<std::size_t>(i)].t);
            windowed.push_back(m / fit);
        }
        double reach = 0;
        for (const SphRun *r : rs)
            reach = std::max(reach, r->intervals.back().time_s / std::sqrt(r->config.scale));
        out[setup] = {{"froude_time_s", times}, {"factor", windowed}, {"factor_windowed", windowed},
                      {"smoothing", "window"},  {"runs", rs.size()},  {"end_froude_time_s", reach}};
        if (!smooth || v.size() < min_smoothed)
            continue;
        // Froude time over the last point's, so the quadratic's columns are of one size.
        const double t_last = v.back().t;
        std::vector<std::vector<double>> X;
        std::vector<double> y;
        for (const auto &x : v) {
            const double u = x.t / t_last;
            X.push_back({1.0, u, u * u});
            y.push_back(x.measured / x.fitted);
        }
        const RobustFit rf = fit_robust(X, y, {"const", "u", "u2"});
        json factors = json::array();
        std::size_t rejected = 0;
        bool finite = true;
        for (std::size_t i = 0; i < X.size(); ++i) {
            const double f = rf.fit.predict(X[i]);
            finite = finite && std::isfinite(f) && f > 0;
            factors.push_back(f);
            rejected += rf.weights[i] == 0.0 ? 1 : 0;
        }
        if (!finite) // a degenerate fit (no spread at all): the window's profile stays
            continue;
        auto &o = out[setup];
        o["factor"] = factors;
        o["smoothing"] = "robust quadratic";
        o["quadratic"] = rf.fit.to_json();
        o["quadratic"]["u"] = "Froude time / " + std::to_string(t_last) + " s";
        o["intervals_rejected"] = rejected;
    }
    return out;
}

// How a busy rank's compute splits between the three segments of a step, from the calibration
// runs within the cores (predict --time-sharing-overhead replay): their CPU time before each
// exchange, or for reports before session 40 their phase timers:
// before the migration (momentum's part of the compute phase, the kicks), before the ghosts
// (mirrors, packing), before the density refresh (grid, search, id sort, continuity's part).
// The compute phase holds both passes: continuity's part is its share of the operations per
// candidate counted in model/NOTES.md ("Flops and bytes"), about 50 of 114.
namespace {
json segment_shares(const std::vector<const SphRun *> &runs) {
    // Measured where the reports carry it (session 40): each busy rank's CPU time before each
    // exchange. Session 40's calibration runs measured 0.31-0.37 / 0.00 / 0.63-0.69 on Cell+List
    // and Cell+Table (the timer split below within 0.01) and 0.47 / 0.01 / 0.52 on Cell+Sorted
    // (the timer split 0.54 / 0.01 / 0.45: its continuity is not 0.44 of its compute).
    // A 1-rank run makes no exchange: only runs of 2 or more ranks measure the segments.
    std::vector<const SphRun *> multi;
    for (const SphRun *r : runs)
        if (r->config.ranks > 1)
            multi.push_back(r);
    const bool measured =
        !multi.empty() && std::all_of(multi.begin(), multi.end(), [](const SphRun *r) {
            return std::all_of(r->intervals.begin(), r->intervals.end(), [](const auto &iv) {
                return std::all_of(iv.ranks.begin(), iv.ranks.end(),
                                   [](const RankStats &rk) { return rk.has_segment_cpu; });
            });
        });
    constexpr double continuity_share = 0.44;
    std::array<double, 3> sum{};
    for (const SphRun *r : measured ? multi : runs)
        for (const auto &iv : r->intervals)
            for (const auto &rk : iv.ranks) {
                if (rk.steps < 1 || rk.field_mean <= 0)
                    continue;
                if (measured) {
                    for (std::size_t k = 0; k < sum.size(); ++k)
                        sum[k] += rk.segment_cpu_s[k];
                    continue;
                }
                const double comp = rk.timer("comp_s");
                sum[0] += (1 - continuity_share) * comp + rk.timer("integrate_s");
                sum[1] += rk.timer("boundary_s") + rk.timer("pack_s");
                sum[2] += rk.timer("grid_s") + rk.timer("pairs_s") + rk.timer("idsort_s") +
                          continuity_share * comp;
            }
    const double total = sum[0] + sum[1] + sum[2];
    if (!(total > 0))
        return nullptr;
    return {{"before_migration", sum[0] / total},
            {"before_ghosts", sum[1] / total},
            {"before_densities", sum[2] / total},
            {"method", measured ? "busy ranks of the calibration runs within the cores: their "
                                  "CPU time before each exchange (sph cpu_before_s)"
                                : "busy ranks of the calibration runs within the cores: compute "
                                  "phase split 0.44 / 0.56 between continuity and momentum"}};
}
} // namespace

json gauge_elasticity(const std::vector<SphRun> &runs,
                      const std::vector<std::vector<double>> &interval_gauges, int cores) {
    constexpr std::size_t min_points_per_group = 4;
    struct Point {
        double x, y, t;
    };
    std::vector<std::vector<Point>> groups; // per run and rank
    for (std::size_t i = 0; i < runs.size(); ++i) {
        const auto &r = runs[i];
        if (cores > 0 && r.config.ranks * r.config.threads > cores)
            continue;
        const std::size_t n = r.intervals.size();
        if (interval_gauges[i].size() != n || n == 0)
            continue;
        const std::size_t ranks = r.intervals.front().ranks.size();
        for (std::size_t k = 0; k < ranks; ++k) {
            std::vector<Point> pts;
            for (std::size_t v = 0; v < n; ++v) {
                if (k >= r.intervals[v].ranks.size())
                    continue;
                const auto &rk = r.intervals[v].ranks[k];
                const double g = interval_gauges[i][v];
                const double c = rk.compute_s();
                if (rk.field <= 0 || rk.interactions <= 0 || rk.steps <= 0 || !(c > 0) || !(g > 0))
                    continue;
                pts.push_back({std::log(g), std::log(c / rk.steps / rk.interactions),
                               (static_cast<double>(v) + 0.5) / static_cast<double>(n)});
            }
            if (pts.size() >= min_points_per_group)
                groups.push_back(std::move(pts));
        }
    }
    std::vector<std::string> terms{"gauge"};
    for (std::size_t g = 0; g < groups.size(); ++g)
        for (const char *part : {"", "_t", "_t2"})
            terms.push_back("group" + std::to_string(g) + part);
    std::vector<std::vector<double>> X;
    std::vector<double> y;
    for (std::size_t g = 0; g < groups.size(); ++g)
        for (const auto &p : groups[g]) {
            std::vector<double> row(terms.size(), 0.0);
            row[0] = p.x;
            row[1 + 3 * g] = 1;
            row[2 + 3 * g] = p.t;
            row[3 + 3 * g] = p.t * p.t;
            X.push_back(std::move(row));
            y.push_back(p.y);
        }
    if (groups.empty() || y.size() <= terms.size() + 2)
        return nullptr;
    LinearFit f;
    try {
        f = fit_linear(X, y, terms);
    } catch (const std::invalid_argument &) {
        return nullptr; // no spread of the gauge left once each group's trend is out
    }
    return {{"value", f.coef[0]},
            {"se", f.se[0]},
            {"points", y.size()},
            {"groups", groups.size()},
            {"method", "least squares of ln(compute per step per interaction) of the busy "
                       "rank-intervals of the runs within the cores on ln(the interval's gauge), "
                       "with an intercept, slope and curvature in the run's time per run and "
                       "rank (each rank's level and the flow's trend); ranks with 4 or more "
                       "intervals"}};
}

json gauge_elasticity_between_repeats(const std::vector<SphRun> &runs, int cores) {
    // Repeats of one configuration do the same work; what differs between them is the host.
    using Key = std::tuple<std::string, std::string, std::string, double, double, std::int64_t, int,
                           int, int, std::string, bool>;
    std::map<Key, std::vector<std::pair<double, double>>> repeats; // (ln gauge, ln cost)
    for (const auto &r : runs) {
        const auto &c = r.config;
        if (cores > 0 && c.ranks * c.threads > cores)
            continue;
        double compute = 0, work = 0;
        for (const auto &iv : r.intervals)
            for (const auto &rk : iv.ranks) {
                compute += rk.compute_s();
                work += rk.interactions * static_cast<double>(rk.steps);
            }
        const double g = r.gauge_per_sample_s();
        if (!(compute > 0) || !(work > 0) || !(g > 0))
            continue;
        repeats[{c.setup, c.grid, c.boundary, c.scale, c.delta, c.steps, c.ranks, c.threads,
                 c.nodes, c.decomposition, c.overlap}]
            .emplace_back(std::log(g), std::log(compute / work));
    }
    std::vector<std::string> terms{"gauge"};
    std::vector<const std::vector<std::pair<double, double>> *> groups;
    for (const auto &[key, pts] : repeats)
        if (pts.size() >= 2) {
            groups.push_back(&pts);
            terms.push_back("configuration" + std::to_string(groups.size() - 1));
        }
    std::vector<std::vector<double>> X;
    std::vector<double> y;
    for (std::size_t g = 0; g < groups.size(); ++g)
        for (const auto &[lg, lc] : *groups[g]) {
            std::vector<double> row(terms.size(), 0.0);
            row[0] = lg;
            row[1 + g] = 1;
            X.push_back(std::move(row));
            y.push_back(lc);
        }
    if (groups.empty() || y.size() < terms.size() + 2)
        return nullptr;
    LinearFit f;
    try {
        f = fit_linear(X, y, terms);
    } catch (const std::invalid_argument &) {
        return nullptr; // the repeats' gauges all alike
    }
    return {{"value", f.coef[0]},
            {"se", f.se[0]},
            {"runs", y.size()},
            {"configurations", groups.size()},
            {"method", "least squares of ln(compute per interaction) of the repeated "
                       "configurations' runs within the cores on ln(the run's gauge), a level "
                       "per configuration: each run's gauge averages all its samples, so its "
                       "noise does not flatten the slope"}};
}

// The wall time no phase timer holds: a run's wall_s over its steps, less the slowest rank's
// timers summed per interval (every step ends in an exchange, so the slowest rank sets it). It
// is the run's own bookkeeping between the timed phases (each interval's record and gathers,
// the progress line, the barrier at the end): measured at 34-44 us a step on 2 ranks and 5-7
// on 1 in session 94's jobs, 3-4 % of a half-scale Cell+Sorted run's wall, which no cost term
// sees (they are fitted on the timers). Per layout (ranks x threads), the median over the
// calibration runs of that layout; predict adds it per step (model/NOTES.md, session 94).
double untimed_s_per_step(const SphRun &r) {
    double timed = 0, steps = 0;
    for (const auto &iv : r.intervals) {
        double slowest = 0;
        for (const auto &rk : iv.ranks) {
            double t = 0;
            for (const auto &[key, v] : rk.timers)
                t += v;
            slowest = std::max(slowest, t);
        }
        timed += slowest;
        if (!iv.ranks.empty())
            steps += iv.ranks.front().steps;
    }
    return steps > 0 ? (r.wall_s - timed) / steps : 0.0;
}

json untimed_per_step(const std::vector<SphRun> &runs) {
    std::map<std::pair<int, int>, std::vector<double>> by_layout;
    for (const auto &r : runs)
        by_layout[{r.config.ranks, r.config.threads}].push_back(untimed_s_per_step(r));
    json layouts = json::array();
    for (const auto &[layout, v] : by_layout) {
        const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
        layouts.push_back({{"ranks", layout.first},
                           {"threads", layout.second},
                           {"runs", v.size()},
                           {"median_s", median(v)},
                           {"min_s", *lo},
                           {"max_s", *hi}});
    }
    return {{"method", "per run: (wall_s - the slowest rank's phase timers summed per interval) / "
                       "steps; per layout (ranks x threads) the median over the calibration "
                       "runs; predict adds it to every step (a layout the calibration did not "
                       "run: the nearest rank count's, at the same thread count if run)"},
            {"layouts", layouts}};
}

double untimed_s_per_step_for(const json &model, int ranks, int threads) {
    if (!model.contains("untimed_per_step"))
        return 0.0;
    const json *best = nullptr;
    auto better = [&](const json &l) {
        if (!best)
            return true;
        const bool same = l.at("threads").get<int>() == threads;
        const bool best_same = best->at("threads").get<int>() == threads;
        if (same != best_same)
            return same;
        const int d = std::abs(l.at("ranks").get<int>() - ranks);
        const int best_d = std::abs(best->at("ranks").get<int>() - ranks);
        return d < best_d ||
               (d == best_d && l.at("ranks").get<int>() > best->at("ranks").get<int>());
    };
    for (const auto &l : model.at("untimed_per_step").at("layouts"))
        if (better(l))
            best = &l;
    return best ? best->at("median_s").get<double>() : 0.0;
}

// The pipeline bubble of time-shared cores (session 80, model/NOTES.md): the step replay
// (replay_time_shared) fed each interval's measured CPU per segment (sph cpu_before_s) gives
// every time-shared validation run's step within 0.5-2.5 % where some core serves one busy rank
// (3-rank runs, equal-slab dam breaks on 4 ranks), but 10-16 % short where every core
// time-shares two busy ranks (the balanced dam break and the half-scale still tank on 4 ranks):
// there both ranks of a core wait, polling, for a neighbour the other core has not run yet (a
// scheduler trace shows 12 % of the busiest core in 2 us yield-to-yield turns), which the
// replay's order never makes. Fitted here on the calibration's own time-shared runs (one
// node, one-thread ranks bound round-robin), per interval: measured step / replayed step - 1
// = a + k phi, phi = sharing_bubble_phi of the measured CPU. Predict multiplies a replayed step
// by 1 + k phi: the slope, what every core's second busy rank adds over the runs where some core
// serves one (a, 1-2 % on the Zen 4 host, 2.5-8 % on the earlier ones, is what the replay misses
// in those too, and the model did not add it there before either). null unless at least 3
// intervals have phi >= 0.5 (two busy ranks on every core) and 3 have phi < 0.5.
json sharing_bubble(const std::vector<SphRun> &runs, int cores) {
    std::vector<std::vector<double>> X;
    std::vector<double> y;
    json per_run = json::array();
    int full = 0, partial = 0;
    for (const auto &r : runs) {
        const int P = r.config.ranks;
        if (!time_shared(r, cores) || r.config.threads != 1 || r.config.nodes != 1 ||
            r.config.overlap || r.placement_pus.size() != static_cast<std::size_t>(P))
            continue;
        // Bound round-robin as scripts/mpirun.sh binds them (rank r with rank r mod cores).
        bool round_robin = true;
        std::vector<int> core_of(static_cast<std::size_t>(P));
        for (int k = 0; k < P; ++k) {
            core_of[static_cast<std::size_t>(k)] = k % cores;
            round_robin = round_robin && r.placement_pus[static_cast<std::size_t>(k)] >= 0 &&
                          r.placement_pus[static_cast<std::size_t>(k)] ==
                              r.placement_pus[static_cast<std::size_t>(k % cores)];
        }
        if (!round_robin)
            continue;
        double phi_sum = 0, loss_sum = 0;
        int n = 0;
        for (const auto &iv : r.intervals) {
            if (iv.ranks.size() != static_cast<std::size_t>(P) ||
                !std::all_of(iv.ranks.begin(), iv.ranks.end(),
                             [](const RankStats &k) { return k.has_segment_cpu && k.steps >= 1; }))
                continue;
            std::vector<std::array<double, 3>> cpu;
            std::vector<double> total;
            double longest = 0;
            for (const auto &rk : iv.ranks) {
                cpu.push_back({rk.segment_cpu_s[0] / rk.steps, rk.segment_cpu_s[1] / rk.steps,
                               rk.segment_cpu_s[2] / rk.steps});
                total.push_back(cpu.back()[0] + cpu.back()[1] + cpu.back()[2]);
                double timers = 0;
                for (const auto &[name, v] : rk.timers)
                    timers += v;
                longest = std::max(longest, timers / rk.steps);
            }
            if (!(*std::max_element(total.begin(), total.end()) > 0))
                continue;
            const double replayed = replay_time_shared(cpu, core_of, default_replay_slice_s).step_s;
            if (!(replayed > 0))
                continue;
            const double phi = sharing_bubble_phi(total, core_of);
            X.push_back({1.0, phi});
            y.push_back(longest / replayed - 1);
            phi_sum += phi;
            loss_sum += y.back();
            (phi >= 0.5 ? full : partial) += 1;
            ++n;
        }
        if (n > 0)
            per_run.push_back({{"run", r.path},
                               {"intervals", n},
                               {"phi_mean", phi_sum / n},
                               {"loss_mean", loss_sum / n}});
    }
    if (full < 3 || partial < 3)
        return nullptr;
    const LinearFit f = fit_linear(X, y, {"const", "phi"});
    return {{"per_phi", f.coef[1]},
            {"per_phi_se", f.se[1]},
            {"intercept", f.coef[0]},
            {"intercept_se", f.se[0]},
            {"r2", f.r2},
            {"rse", f.rse},
            {"intervals", f.points},
            {"intervals_phi_at_least_half", full},
            {"intervals_phi_below_half", partial},
            {"slice_s", default_replay_slice_s},
            {"runs", per_run},
            {"method", "per interval of the time-shared calibration runs (one node, one-thread "
                       "ranks bound round-robin): measured step (the longest rank's timers) over "
                       "the step replayed from the measured CPU per segment, minus 1, = intercept "
                       "+ per_phi x phi (least squares); phi: per core, the second "
                       "busiest rank's CPU over the busiest's, the least over the cores"},
            {"uses", "predict multiplies a replayed time-shared step by 1 + per_phi x phi of its "
                     "predicted compute (--time-sharing-bubble on, the default)"}};
}

json run_drift(const std::vector<SphRun> &runs, int cores) {
    constexpr std::array<double, 8> edges{0, 0.25, 0.5, 1, 2, 4, 8, 16}; // s since the start
    constexpr std::size_t bins = edges.size() - 1;                       // the last one open
    auto bin_of = [&](double t) {
        std::size_t b = 0;
        while (b + 1 < bins && t >= edges[b + 1])
            ++b;
        return b;
    };
    struct Point {
        std::size_t bin;
        double log_gauge, weight;
    };
    // Each run's busy rank-intervals within the cores, at the middle of the interval (rank 0's
    // timers summed: the run's wall time).
    std::vector<std::vector<Point>> points(runs.size());
    for (std::size_t i = 0; i < runs.size(); ++i) {
        const SphRun &r = runs[i];
        if (cores > 0 && r.config.ranks * r.config.threads > cores)
            continue; // descheduled time in its timers and gauge
        double t = 0;
        for (const auto &iv : r.intervals) {
            if (iv.ranks.empty())
                continue;
            double wall = 0;
            for (const auto &[k, v] : iv.ranks[0].timers)
                wall += v;
            const std::size_t b = bin_of(t + wall / 2);
            t += wall;
            for (const auto &rk : iv.ranks)
                if (rk.gauge_samples > 0 && rk.gauge_cpu_s > 0 && rk.compute_s() > 0)
                    points[i].push_back(
                        {b, std::log(rk.gauge_cpu_s / rk.gauge_samples), rk.compute_s()});
        }
    }
    // ln gauge = the run's level + f(bin), weighted least squares by alternating projections,
    // f = 0 in the first bin any run reaches; only runs spanning two bins or more inform f.
    std::vector<const std::vector<Point> *> spanning;
    std::array<bool, bins> seen{};
    for (const auto &p : points) {
        std::set<std::size_t> b;
        for (const auto &q : p)
            b.insert(q.bin);
        if (b.size() > 1) {
            spanning.push_back(&p);
            for (std::size_t x : b)
                seen[x] = true;
        }
    }
    if (spanning.size() < 2)
        return nullptr;
    std::array<double, bins> f{};
    for (int iteration = 0; iteration < 500; ++iteration) {
        std::array<double, bins> num{}, den{};
        for (const auto *p : spanning) {
            double a = 0, w = 0;
            for (const auto &q : *p) {
                a += q.weight * (q.log_gauge - f[q.bin]);
                w += q.weight;
            }
            a /= w;
            for (const auto &q : *p) {
                num[q.bin] += q.weight * (q.log_gauge - a);
                den[q.bin] += q.weight;
            }
        }
        std::array<double, bins> next{};
        std::optional<double> first;
        for (std::size_t b = 0; b < bins; ++b)
            if (seen[b]) {
                next[b] = num[b] / den[b];
                if (!first)
                    first = next[b];
            }
        double change = 0;
        for (std::size_t b = 0; b < bins; ++b) {
            next[b] = seen[b] ? next[b] - *first : 0.0;
            change = std::max(change, std::abs(next[b] - f[b]));
        }
        f = next;
        if (change < 1e-12)
            break;
    }
    // A bin no run reached takes the last reached one's value (the host's drift levels off:
    // model/NOTES.md, session 79); before the first reached, 0.
    double last = 0;
    json profile = json::array(), edges_json = json::array();
    for (std::size_t b = 0; b < bins; ++b) {
        if (seen[b])
            last = f[b];
        f[b] = last;
        profile.push_back(f[b]);
        edges_json.push_back(edges[b]);
    }
    // Each grid, thread count and setup's calibration: the compute-weighted mean of exp(f) over
    // its rank-intervals, the drift its runs' speed already holds.
    using Key = std::tuple<std::string, int, std::string>;
    std::map<Key, std::pair<double, double>> held;
    for (std::size_t i = 0; i < runs.size(); ++i)
        for (const auto &q : points[i]) {
            auto &[sum, weight] =
                held[{runs[i].config.grid, runs[i].config.threads, runs[i].config.setup}];
            sum += q.weight * std::exp(f[q.bin]);
            weight += q.weight;
        }
    json per = json::array();
    for (const auto &[key, v] : held)
        per.push_back({{"grid", std::get<0>(key)},
                       {"threads", std::get<1>(key)},
                       {"setup", std::get<2>(key)},
                       {"mean_drift", v.first / v.second}});
    return {{"edges_s", edges_json},
            {"ln_profile", profile},
            {"runs", spanning.size()},
            {"per_setup", per},
            {"method",
             "each calibration run's busy rank-intervals within the cores: ln(speed-gauge "
             "CPU seconds per sample) = the run's level + a profile over the time since "
             "the run started (bins from edges_s, the last open; least squares weighted "
             "by compute, the first bin reached 0; a bin no run reached takes the last "
             "reached one's value); per_setup.mean_drift: exp(profile) averaged over "
             "the compute of that setup's runs. predict --run-drift on puts each "
             "interval at exp(profile at its time) / mean_drift (model/NOTES.md, "
             "session 79)"}};
}

double gauge_elasticity_for(const json &speed_gauge) {
    if (!speed_gauge.is_object() || !speed_gauge.value("applied", false) ||
        !speed_gauge.contains("elasticity"))
        return 1.0;
    return speed_gauge.at("elasticity").value("used", 1.0);
}

json speed_normalise(std::vector<SphRun> &runs, SpeedGauge mode, GaugeReference rule,
                     GaugeElasticity elasticity_rule, int cores) {
    json out{{"applied", false}};
    if (mode == SpeedGauge::off) {
        out["reason"] = "calibrate --speed-gauge off";
        return out;
    }
    std::vector<double> gauge;
    for (const auto &r : runs) {
        const double g = r.gauge_per_sample_s();
        if (g <= 0) {
            out["reason"] = "'" + r.path +
                            "' has no speed-gauge samples (sph --speed-gauge-every 0, or a report "
                            "from before session 50)";
            return out;
        }
        gauge.push_back(g);
    }
    if (gauge.empty()) {
        out["reason"] = "no runs";
        return out;
    }
    const double pooled = median(gauge);
    // Before any time is scaled: the host's drift within runs, from the runs as measured.
    const json drift = run_drift(runs, cores);
    // Each run's reference: its grid and thread count's median gauge, or the pooled one.
    std::map<std::pair<std::string, int>, std::vector<double>> groups;
    for (std::size_t i = 0; i < runs.size(); ++i)
        groups[{runs[i].config.grid, runs[i].config.threads}].push_back(gauge[i]);
    std::map<std::pair<std::string, int>, double> group_reference;
    json references = json::array();
    for (const auto &[key, g] : groups) {
        group_reference[key] = median(g);
        references.push_back({{"grid", key.first},
                              {"threads", key.second},
                              {"reference_cpu_s_per_sample", group_reference[key]},
                              {"runs", g.size()}});
    }
    // The gauge around each interval (the run mode's elasticity is estimated on them too).
    const auto pooling =
        mode == SpeedGauge::interval_mean ? SphRun::Pooling::mean : SphRun::Pooling::median;
    std::vector<std::vector<double>> interval_gauges;
    for (const auto &r : runs)
        interval_gauges.push_back(r.interval_gauges_s(speed_gauge_half_window, pooling));
    // Estimated whatever the rule (a diagnostic of how far the runs follow the gauge), used
    // with fitted only.
    double beta = 1;
    json elasticity = gauge_elasticity(runs, interval_gauges, cores);
    const json between = gauge_elasticity_between_repeats(runs, cores);
    // The estimate fitted uses: between repeats (unbiased), else within runs.
    const json &estimate = !between.is_null() ? between : elasticity;
    if (estimate.is_null()) {
        elasticity = {{"used", 1.0},
                      {"reason", "too few busy rank-intervals within the cores to estimate it: "
                                 "the factor applied whole"}};
    } else if (elasticity_rule == GaugeElasticity::one) {
        elasticity["used"] = 1.0;
        elasticity["reason"] = "calibrate --speed-gauge-elasticity one: the factor applied whole";
    } else if (estimate.at("se").get<double>() > max_elasticity_se) {
        elasticity["used"] = 1.0;
        elasticity["reason"] = "standard error above " + std::to_string(max_elasticity_se) +
                               ": the factor applied whole";
    } else {
        beta = estimate.at("value").get<double>();
        elasticity["used"] = beta;
        elasticity["reason"] = !between.is_null()
                                   ? "calibrate --speed-gauge-elasticity fitted: the estimate "
                                     "between repeats"
                                   : "calibrate --speed-gauge-elasticity fitted: the estimate "
                                     "within runs (no repeated configuration)";
    }
    elasticity["between_repeats"] = between;
    json list = json::array();
    std::vector<double> logs;
    // The calibration's compute as measured and at the reference speed, per grid, thread count
    // and setup (and the runs): their ratio is the host's mean speed over those runs against
    // the median run's. Per setup because the model's compute of a setup is that setup's level
    // on that grid, so its host speed is that of the same runs (session 76); pooled, session 75.
    using SetupKey = std::tuple<std::string, int, std::string>;
    auto setup_compute = [&runs] {
        std::map<SetupKey, std::pair<double, int>> c;
        for (const auto &r : runs) {
            auto &[s, n] = c[{r.config.grid, r.config.threads, r.config.setup}];
            for (const auto &iv : r.intervals)
                for (const auto &rk : iv.ranks)
                    s += rk.compute_s();
            ++n;
        }
        return c;
    };
    auto total = [](const std::map<SetupKey, std::pair<double, int>> &c) {
        double s = 0;
        for (const auto &[key, v] : c)
            s += v.first;
        return s;
    };
    const auto setup_measured = setup_compute();
    const double compute_measured = total(setup_measured);
    for (std::size_t i = 0; i < runs.size(); ++i) {
        const double reference =
            rule == GaugeReference::grid
                ? group_reference.at({runs[i].config.grid, runs[i].config.threads})
                : pooled;
        const double factor = gauge[i] / reference;
        json row{{"path", runs[i].path},
                 {"gauge_cpu_s_per_sample", gauge[i]},
                 {"factor", factor},
                 {"applied_factor", std::pow(factor, beta)}};
        if (mode == SpeedGauge::interval || mode == SpeedGauge::interval_mean) {
            std::vector<double> inverse, factors, applied;
            for (double g : interval_gauges[i]) {
                factors.push_back(g / reference);
                applied.push_back(std::pow(g / reference, beta));
                inverse.push_back(1 / applied.back());
            }
            runs[i].scale_times(inverse);
            row["interval_factors"] = factors;
            if (beta != 1)
                row["interval_applied_factors"] = applied;
        } else {
            runs[i].scale_times(1 / std::pow(factor, beta));
        }
        logs.push_back(std::log(factor));
        list.push_back(row);
    }
    const double mean = std::accumulate(logs.begin(), logs.end(), 0.0) / logs.size();
    double ss = 0;
    for (double l : logs)
        ss += (l - mean) * (l - mean);
    const std::string divided =
        elasticity_rule == GaugeElasticity::fitted && beta != 1
            ? "divided by the factor raised to the elasticity the runs show (elasticity.used)"
            : "divided by it";
    out = {{"applied", true},
           {"mode", mode == SpeedGauge::interval        ? "interval"
                    : mode == SpeedGauge::interval_mean ? "interval-mean"
                                                        : "run"},
           {"reference_cpu_s_per_sample", pooled},
           {"reference", rule == GaugeReference::grid ? "grid" : "pooled"},
           {"method", mode != SpeedGauge::run
                          ? "each interval's speed-gauge CPU seconds per sample, pooled over +-" +
                                std::to_string(speed_gauge_half_window) + " interval(s) as the " +
                                (mode == SpeedGauge::interval ? "median" : "mean") +
                                " of the rank-intervals weighted by their compute, over the runs' "
                                "median (each run's whole gauge) is the host's speed factor "
                                "then; every time the interval measured is " +
                                divided + ", so the model is at the median run's speed"
                          : "each run's speed-gauge CPU seconds per sample over the runs' "
                            "median is the host's speed factor during the run; every time the "
                            "run measured is " +
                                divided + ", so the model is at the median run's speed"},
           {"log_sd", logs.size() > 1 ? std::sqrt(ss / static_cast<double>(logs.size() - 1)) : 0.0},
           {"runs", list}};
    out["elasticity"] = elasticity;
    out["run_drift"] = drift;
    const auto setup_at_reference = setup_compute();
    const double compute_at_reference = total(setup_at_reference);
    if (compute_measured > 0 && compute_at_reference > 0)
        out["mean_factor"] = {
            {"value", compute_measured / compute_at_reference},
            {"method", "the calibration runs' compute as measured over their compute at the "
                       "reference speed: the host's mean speed over them against the median "
                       "run's (below 1: faster on average, its fast spells); per_setup, the "
                       "same over the runs of one grid, thread count and setup. predict "
                       "--host-speed mean multiplies a prediction's compute by its setup's "
                       "(session 76), mean-pooled by this one (session 75), median by neither "
                       "(model/NOTES.md, sessions 74-76)"}};
    if (out.contains("mean_factor")) {
        json per = json::array();
        for (const auto &[key, measured] : setup_measured) {
            const double ref = setup_at_reference.at(key).first;
            if (measured.first > 0 && ref > 0)
                per.push_back({{"grid", std::get<0>(key)},
                               {"threads", std::get<1>(key)},
                               {"setup", std::get<2>(key)},
                               {"runs", measured.second},
                               {"value", measured.first / ref}});
        }
        out["mean_factor"]["per_setup"] = per;
    }
    if (rule == GaugeReference::grid) {
        out["references"] = references;
        out["method"] = out["method"].get<std::string>() +
                        "; the median is of the run's grid and thread count (the gauge's reading "
                        "depends on what runs around it: model/NOTES.md, session 58)";
    }
    return out;
}

json gauge_reference_for(const json &speed_gauge, const std::string &grid, int threads) {
    if (!speed_gauge.is_object() || !speed_gauge.value("applied", false))
        return nullptr;
    if (speed_gauge.contains("references"))
        for (const auto &r : speed_gauge.at("references"))
            if (r.at("grid").get<std::string>() == grid && r.at("threads").get<int>() == threads)
                return r.at("reference_cpu_s_per_sample");
    return speed_gauge.at("reference_cpu_s_per_sample");
}

json calibrate(const json &header, const json &machine, const std::vector<SphRun> &measured,
               const CalibrateOptions &opt) {
    // Every time below at the gauge's reference speed where the runs carry it.
    std::vector<SphRun> runs = measured;
    const json speed_gauge =
        speed_normalise(runs, opt.speed_gauge, opt.gauge_reference, opt.gauge_elasticity,
                        machine.contains("topology") && machine.at("topology").is_object()
                            ? machine.at("topology").value("cores", 0)
                            : 0);
    if (runs.empty())
        throw UsageError("calibrate needs at least one SPH report (--runs)");
    const std::string host = machine.value("host", "");
    for (const auto &r : runs)
        if (r.host != host && !opt.allow_other_host)
            throw UsageError("'" + r.path + "' was measured on host '" + r.host +
                             "' but the machine profile is of '" + host +
                             "' (pass --allow-other-host to mix them)");
    const CommModel comm = CommModel::from_profile(machine); // checks the section
    (void)comm;
    const int cores = machine.at("topology").value("cores", 1);

    std::vector<Point> all;
    std::map<std::pair<std::string, int>, std::vector<Point>> by_grid_threads;
    std::map<std::string, std::vector<Point>> by_grid, by_setup;
    std::vector<SphRun> own_cores; // runs within the core count
    json traces = json::object(), sources = json::array();
    double record_bytes = 0;
    for (std::size_t i = 0; i < runs.size(); ++i) {
        const auto &r = runs[i];
        const auto pts = points_of(r, static_cast<int>(i));
        all.insert(all.end(), pts.begin(), pts.end());
        // A time-shared run's timers include the time its ranks were descheduled: it sets
        // the time-sharing overhead, not the compute cost.
        // A rank without field particles is idle in the model (predict prices no compute for
        // it), so its few tens of microseconds of grid and wall bookkeeping per step stay out
        // of the cost fit and its level: in a 2-rank half-scale dam break they are 10 % of the
        // busy rank's Cell+Sorted compute, and folded into the level they put every busy rank
        // at scale 1 that much high.
        if (!time_shared(r, cores)) {
            auto &g = by_grid_threads[{r.config.grid, r.config.threads}];
            std::copy_if(pts.begin(), pts.end(), std::back_inserter(g),
                         [](const Point &p) { return p.work.field > 0; });
            own_cores.push_back(r);
        }
        auto &gg = by_grid[r.config.grid];
        gg.insert(gg.end(), pts.begin(), pts.end());
        auto &gs = by_setup[r.config.setup];
        gs.insert(gs.end(), pts.begin(), pts.end());
        record_bytes = r.record_bytes;
        // Per setup keep the trace reaching furthest in Froude-scaled time.
        const Trace t = trace_of(r);
        const std::string key = r.config.setup;
        const double reach = t.end_time() / std::sqrt(t.scale);
        if (!traces.contains(key) || traces[key]["end_time_s"].get<double>() /
                                             std::sqrt(traces[key]["scale"].get<double>()) <
                                         reach) {
            traces[key] = t.to_json();
            traces[key]["end_time_s"] = t.end_time();
        }
        // As measured (the fit's copy may be at the gauge's reference speed).
        double cost = 0;
        for (const auto &iv : measured[i].intervals)
            for (const auto &rk : iv.ranks)
                cost += rk.compute_s();
        sources.push_back({{"path", r.path},
                           {"setup", r.config.setup},
                           {"grid", r.config.grid},
                           {"scale", r.config.scale},
                           {"delta", r.config.delta},
                           {"ranks", r.config.ranks},
                           {"threads", r.config.threads},
                           {"steps", r.config.steps},
                           {"wall_s", measured[i].wall_s},
                           {"cpu_s", cost},
                           {"git_commit", r.git_commit}});
    }

    json model = header;
    model["machine"] = {{"host", host},
                        {"cores", machine.at("topology").value("cores", 1)},
                        {"peak_gflops", machine.at("peak_gflops")},
                        {"stream_triad_GBps", machine.at("stream_triad_GBps")},
                        {"hockney", machine.at("hockney")}};
    if (machine.contains("exchange"))
        model["machine"]["exchange"] = machine.at("exchange");
    model["calibration_runs"] = sources;
    model["speed_gauge"] = speed_gauge;
    // The calibration runs of 2+ threads per rank: the mode of the vCPUs' latency each ran in
    // (sph's core latency gauge), beside the validation runs' (validate: core_latency).
    json latency = json::array();
    for (const auto &r : measured)
        if (json c = r.core_latency_json(); !c.is_null()) {
            c["path"] = r.path;
            latency.push_back(c);
        }
    model["core_latency"] = latency;
    model["record_bytes"] = record_bytes;
    // The thesis' laws, per setup (a still tank packs its particles differently from a
    // collapsing dam) and pooled; interactions (ordered pairs acting on an owned particle)
    // drive the compute cost.
    auto laws = [](const std::vector<Point> &pts) {
        return json{
            {"pairs", regression(pts, [](const Point &p) { return p.pairs; })},
            {"exports", regression(exporting(pts), [](const Point &p) { return p.exported; })},
            {"interactions", regression(pts, [](const Point &p) { return p.work.interactions; })}};
    };
    json regs = json::object();
    for (const auto &[setup, pts] : by_setup)
        regs[setup] = laws(pts);
    regs["pooled"] = laws(all);
    regs["thesis"] = {
        {"pairs", {{"m", 19.451}, {"m_se", 0.4994}, {"r", -589.96}, {"r_se", 299.6}}},
        {"exports", {{"m", 0.112845}, {"m_se", 0.004522}, {"r", -4.02341}, {"r_se", 2.713}}}};
    model["regressions"] = regs;
    json compute = json::array();
    for (const auto &[key, pts] : by_grid_threads) {
        json c = compute_fit(pts, runs, opt.term_selection, opt.time_profile, opt.fit_weights,
                             opt.run_level, opt.walls_term, opt.bound_item_costs, opt.cv_hold_out);
        c["grid"] = key.first;
        c["threads"] = key.second;
        std::vector<const SphRun *> mine;
        for (const SphRun &r : own_cores)
            if (r.config.grid == key.first && r.config.threads == key.second)
                mine.push_back(&r);
        c["segment_shares"] = segment_shares(mine);
        if (opt.time_profile != TimeProfile::none) {
            const bool smooth = opt.time_profile == TimeProfile::froude;
            const bool shape_only = opt.run_level != RunLevelRule::pooled;
            c["time_profile"] = compute_time_profile(c, mine, smooth, shape_only);
            c["time_profile"]["method"] =
                std::string("per setup, measured / fitted compute of the busy ranks of the "
                            "calibration runs by Froude time (interval midpoint / sqrt(scale)), "
                            "rounds at the same times pooled; ") +
                (smooth ? "a quadratic in Froude time fitted to the intervals' ratios by robust "
                          "least squares (bisquare), the ratio of sums over +-2 intervals where "
                          "fewer than 8 intervals (factor_windowed: that ratio everywhere); "
                        : "the ratio of sums over +-2 intervals; ") +
                "predict multiplies the fit by it at the target's Froude time";
        }
        compute.push_back(c);
    }
    if (compute.empty())
        throw UsageError("every calibration run has more ranks x threads than the " +
                         std::to_string(cores) +
                         " cores: the compute cost needs at least one run within them");
    model["compute"] = compute;
    // The band (predict: wall_band) is how far one run lands from a right prediction on this
    // host as its runs are measured: with the gauge applied, each run's level factor carries
    // its speed factor back in; the scatter at one speed is kept beside.
    if (speed_gauge.value("applied", false)) {
        std::map<std::string, double> speed;
        std::map<std::string, std::string> setup_of;
        for (const auto &g : speed_gauge.at("runs"))
            speed[g.at("path").get<std::string>()] =
                g.value("applied_factor", g.at("factor").get<double>());
        for (const auto &r : runs)
            setup_of[r.path] = r.config.setup;
        json as_measured = compute;
        for (auto &c : as_measured) {
            std::map<std::string, std::vector<double>> by_setup;
            for (const auto &f : c.at("run_level").at("runs")) {
                const auto path = f.at("run").get<std::string>();
                by_setup[setup_of.at(path)].push_back(f.at("factor").get<double>() *
                                                      speed.at(path));
            }
            c["run_level"]["scatter"] = scatter_json(level_scatter(by_setup));
        }
        model["level_scatter"] = pooled_level_scatter(as_measured);
        model["level_scatter_at_one_speed"] = pooled_level_scatter(compute);
    } else {
        model["level_scatter"] = pooled_level_scatter(compute);
    }
    model["time_sharing"] = time_sharing(runs, compute, cores);
    model["time_sharing_bubble"] = sharing_bubble(runs, cores);
    model["untimed_per_step"] = untimed_per_step(runs);
    if (json j = jitter(runs, compute, cores, opt.jitter_form); !j.is_null())
        model["jitter"] = j;
    json moves = json::object();
    for (const auto &[grid, pts] : by_grid)
        moves[grid] = cell_move_fit(pts);
    model["cell_moves"] = moves;
    model["roofline"] = roofline(machine, measured); // the runs' own speed
    model["memory"] = memory_model(runs);
    model["traces"] = traces;
    model["disorder"] = disorder_by_setup(own_cores, opt.order_line_gauge);
    return model;
}

} // namespace sphperf::model
