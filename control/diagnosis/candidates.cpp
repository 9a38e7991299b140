#include "control/diagnosis/candidates.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>

#include "control/config_error.hpp"
#include "control/diagnosis/mode_hint.hpp"
#include "control/text_format.hpp"

namespace pvcgel::control::diagnosis::detail {

namespace {
constexpr size_t kModeHints = 2;       ///< residual peaks a mode's grid also starts from
constexpr double kHintDamping = 0.02;  ///< the damping ratio a mode found as a narrow peak starts from
/// How far above a dead zone's threshold the smallest recorded |command| may lie for the recordings to show it.
constexpr double kThresholdReach = 10.0;
}  // namespace

const CandidateResult* fitted_candidate(const DiagnosisResult& res, EffectKind k) {
  for (const auto& c : res.candidates)
    if (c.fitted && c.effect.kind == k) return &c;
  return nullptr;
}

CandidateResult* fitted_candidate(DiagnosisResult& res, EffectKind k) {
  return const_cast<CandidateResult*>(fitted_candidate(std::as_const(res), k));  // NOLINT: the const lookup, on a mutable result
}

bool can_run_together(const Effect& a, const Effect& b) {
  try {
    validate_mixture(std::vector<Effect>{a, b}, "mixture");
    return true;
  } catch (const ConfigError&) {
    return false;
  }
}

Eigen::VectorXd start_at(const Effect& e, Nominal k, const DataScale& scale, const DiagnosisOptions& o,
                         const std::vector<Series>& data) {
  const auto z = FitSpace({e.kind}, scale, false, o, &data).z_of({e}, {});
  Eigen::VectorXd start(z.size() + kNominalParams);
  start << z, k.time_scale, k.shape, k.next;
  return start;
}

std::vector<double> mode_hints(const DiagnosisResult& res, const std::vector<Series>& data,
                               const std::vector<std::vector<double>>& y, const DataScale& scale,
                               const DiagnosisOptions& o) {
  const FitSpace mode({EffectKind::resonance}, scale, false, o, &data);
  return mode_frequency_hints(data, y, res.held_out, res.noise_sigma_um, mode.specs[0].lower, mode.specs[0].upper,
                              kModeHints);
}

void add_mode_starts(FitSpace& space, const std::vector<double>& frequencies_Hz) {
  if (frequencies_Hz.empty()) return;
  auto& f = space.specs[0].starts;
  f.insert(f.end(), frequencies_Hz.begin(), frequencies_Hz.end());
  auto& zeta = space.specs[1].starts;
  if (std::find(zeta.begin(), zeta.end(), kHintDamping) == zeta.end()) zeta.insert(zeta.begin(), kHintDamping);
}

namespace {

/// Coarse grid (the evidence) for every candidate: fills res.candidates with it and returns the two best
/// grid points of each.
Starts grid_starts(DiagnosisResult& res, Problem& problem, const std::vector<Series>& data, const DataScale& scale,
                   const DiagnosisOptions& o, double nuisance_cost) {
  const size_t kinds = kCandidateEffects.size();
  Starts starts(kinds);
  std::vector<CandidateResult> evidence(kinds);
  const auto hints = mode_hints(res, data, problem.predict({}, 1.0, true).y, scale, o);
  run_each("coarse grids", kinds, problem, o, [&](size_t i, Problem& own) {
    const EffectKind kind = kCandidateEffects[i];
    FitSpace space({kind}, scale, false, o, &data);
    if (kind == EffectKind::resonance) add_mode_starts(space, hints);
    // The two best grid points at G's time scale 1, and for a loop also at 0.4: a loop may take back a
    // large share of the nominal's lag (a much faster G), where other loop parameters fit best.
    for (double ts : kind == EffectKind::hysteresis ? std::vector<double>{1.0, 0.4} : std::vector<double>{1.0}) {
      const Nominal k = start_nominal(res, {ts, res.nominal_refit.poly_shape, res.nominal_refit.poly_next_slope});
      const auto grid = coarse_grid(space, [&](const Effect& e) { return own.residual({&e, 1}, k).squaredNorm(); });
      if (ts == 1.0) {  // the evidence: at the nominal's time scale, as for every candidate
        evidence[i].specs = space.specs;
        evidence[i].evidence_r2 = std::max(0.0, 1.0 - grid.front().first / nuisance_cost);
        evidence[i].effect = space.effects(grid.front().second).front();
      }
      for (size_t g = 0; g < std::min<size_t>(grid.size(), 2); ++g) {
        starts[i].emplace_back(grid[g].second.size() + kNominalParams);
        starts[i].back() << grid[g].second, k.time_scale, k.shape, k.next;
      }
    }
  });
  res.candidates.insert(res.candidates.end(), evidence.begin(), evidence.end());
  return starts;
}

/// Where a later pass starts candidate `c`: at its earlier fit, or at its grid point with G's time scale 1
/// when it was not fitted (f as start_nominal has it either way).
Eigen::VectorXd warm_start(const DiagnosisResult& res, const CandidateResult& c, const DataScale& scale,
                           const DiagnosisOptions& o, const std::vector<Series>& data) {
  const Nominal refit{1.0, res.nominal_refit.poly_shape, res.nominal_refit.poly_next_slope};
  return start_at(c.effect, start_nominal(res, c.fitted ? nominal_of(c) : refit), scale, o, data);
}

/// A later pass starts each candidate where the earlier one fitted it (its evidence is the earlier pass's):
/// one start each instead of the grid's two, a refit after a change of one sample of delay or of f's
/// tolerances.
Starts warm_starts(DiagnosisResult& res, const std::vector<CandidateResult>& first, const std::vector<Series>& data,
                   const DataScale& scale, const DiagnosisOptions& o) {
  Starts starts;
  for (const auto& c : first) {
    starts.push_back({warm_start(res, c, scale, o, data)});
    res.candidates.push_back(c);
    res.candidates.back().fitted = false;
  }
  return starts;
}

/// The coarse grid's starts and evidence (grid_starts), and each candidate's earlier fit as a start too
/// (warm_starts), instead of the grid's for all but the earlier pass's `warm.regridded` leaders.
Starts regridded_warm_starts(DiagnosisResult& res, Problem& problem, const WarmStarts& warm,
                             const std::vector<Series>& data, const DataScale& scale, const DiagnosisOptions& o,
                             double nuisance_cost) {
  Starts starts = grid_starts(res, problem, data, scale, o, nuisance_cost);
  const auto& earlier = *warm.candidates;
  for (size_t i = 0; i < res.candidates.size(); ++i) {
    const auto it = std::find_if(earlier.begin(), earlier.end(), [&](const CandidateResult& c) {
      return c.fitted && c.effect.kind == res.candidates[i].effect.kind;
    });
    if (it == earlier.end()) continue;
    const auto start = warm_start(res, *it, scale, o, data);
    if (static_cast<size_t>(it - earlier.begin()) < warm.regridded) starts[i].push_back(start);
    else starts[i] = {start};
  }
  return starts;
}

/// Per recording, one at a time with the others held, the start state of the lowest fit-segment cost at z
/// among those `search(try_start, chosen)` prices (try_start(v) prices v, chosen() is the cheapest so far,
/// the first of equals); `state` the current states (empty: T{} each), `set` puts states in the problem.
/// Leaves the choice set; returns whether it changed.
template <class T, class Set, class Search>
bool choose_start_states(Problem& problem, const FitSpace& space, const Eigen::VectorXd& z, std::vector<T> state,
                         size_t recordings, Set set, Search search) {
  const auto e = space.effects(z);
  const Nominal k = space.g_scale(z);
  state.resize(recordings, T{});
  const auto before = state;
  for (size_t r = 0; r < recordings; ++r) {
    double best = INFINITY;
    T chosen = state[r];
    const auto try_start = [&](T v) {
      state[r] = v;
      set(state);
      const double cost = problem.residual(e, k).squaredNorm();
      if (cost < best) best = cost, chosen = v;
    };
    search(try_start, [&] { return chosen; });
    state[r] = chosen;
  }
  set(state);
  return state != before;
}

/// The branch each recording's loop starts on, by choose_start_states:
/// virgin, rising or falling, then partway along the better side (set_loop_memory: a single step from a
/// hold at another level, the start of a recording made after such a hold), to an eighth of the widest play.
/// A recording that starts after a hold elsewhere or mid-motion starts part of a loop away from virgin, an
/// offset as large as the loop that no effect parameter can take.
bool choose_loop_memory(Problem& problem, const FitSpace& space, const Eigen::VectorXd& z, size_t recordings) {
  const auto set = [&](const std::vector<double>& m) { problem.set_loop_memory(m); };
  return choose_start_states(problem, space, z, problem.loop_memory(), recordings, set,
                             [](const auto& try_start, const auto& chosen) {
    for (double branch : {0.0, 1.0, -1.0}) try_start(branch);
    // Partway: along the better branch's side (from virgin, a quarter of the way to either), then an eighth
    // either side of the best.
    if (const double side = chosen(); side == 0.0) {
      try_start(0.25);
      try_start(-0.25);
    } else {
      for (double share : {0.25, 0.5, 0.75}) try_start(std::copysign(share, side));
    }
    const double centre = chosen();
    for (double d : {-0.125, 0.125})
      if (std::abs(centre + d) < 1.0 && centre + d != 0.0) try_start(centre + d);
  });
}

/// Where each recording's slew limit drive starts, by choose_start_states: at the analysis's start, or where
/// the actuator rests (Problem::set_drive_at_rest). A closed loop from a charged start commands at once what
/// the drive reaches only by slewing there (fresh seed 211's case021); a recording that starts mid-motion
/// finds the drive at its commands (seed 131's case035).
bool choose_drive_at_rest(Problem& problem, const FitSpace& space, const Eigen::VectorXd& z, size_t recordings) {
  const auto set = [&](const std::vector<char>& at_rest) { problem.set_drive_at_rest(at_rest); };
  return choose_start_states(problem, space, z, problem.drive_at_rest(), recordings, set,
                             [](const auto& try_start, const auto&) {
    for (char at_rest : {char{0}, char{1}}) try_start(at_rest);
  });
}

}  // namespace

/// The parameter that chooses between forms fitted in spaces of their own (candidate_spaces), if any.
std::optional<size_t> form_choice(EffectKind kind) {
  if (const auto at = form_flag_index(kind)) return at;
  if (kind == EffectKind::drift) return kDriftWander;
  return std::nullopt;
}

void hold_form(FitSpace& space, EffectKind kind, double value) {
  const auto form = form_choice(kind);
  if (!form) return;
  space.hold(kind, *form, value);
  if (kind == EffectKind::drift && value > 0.0)
    for (size_t i : {1, 2, 3}) space.hold(kind, i, 0.0);  // rate, onset, settling: the spline follows them
}

void hold_form_of(FitSpace& space, const Effect& fitted) {
  if (const auto form = form_choice(fitted.kind)) hold_form(space, fitted.kind, fitted.p[*form]);
}

namespace {

/// The spaces a candidate is fitted in: its own, and for a loop also with the earlier shape
/// (threshold_spread 0), kept only when the free shape does not fit clearly better: on short or
/// closed-loop data the free shape otherwise bends to the fit segment alone. A choice of form (a
/// saturation's placement, asymmetric or bias-dependent dynamics on G's slow pole alone, a drift that
/// wanders) is a space of its own.
std::vector<FitSpace> candidate_spaces(EffectKind kind, const DataScale& scale, const DiagnosisOptions& o,
                                       const std::vector<Series>& data, const TransferFunction& G) {
  std::vector<FitSpace> spaces{FitSpace({kind}, scale, true, o, &data)};
  if (kind == EffectKind::hysteresis) {
    spaces.push_back(spaces.front());
    spaces.back().hold(EffectKind::hysteresis, 2, 0.0);  // spread 0
  } else if (const auto form = form_choice(kind);
             form && (!slow_pole_only_index(kind) || slowest_pole_is_real(G))) {
    spaces.push_back(spaces.front());
    // On the drive; the slow pole alone; a wandering drift (its size set after the fit, from its splines).
    hold_form(spaces.back(), kind, 1.0);
  }
  return spaces;
}

/// One joint fit of a candidate (effect parameters and the nominal refit; gain, offset and initial state by
/// projection) in one of its spaces from one start: the cost it reaches, where, and for a loop the branch
/// each recording starts on, for a slew limit where its drive starts (each chosen before the fit and once
/// more after it).
struct StartFit {
  double cost = INFINITY;
  Eigen::VectorXd z;
  std::vector<double> loop_memory;
  std::vector<char> drive_at_rest;
};

StartFit fit_from(const FitSpace& space, const Eigen::VectorXd& s0, Problem& problem, size_t recordings) {
  StartFit out;
  Eigen::VectorXd z(static_cast<Eigen::Index>(space.specs.size()));
  const Eigen::Index effect_params = s0.size() - kNominalParams;
  z.head(effect_params) = s0.head(effect_params);
  const Nominal k{s0(effect_params), s0(effect_params + 1), s0(effect_params + 2)};
  z.tail(kNominalParams) = space.z_of({space.effects(z).front()}, k).tail(kNominalParams);
  const bool loop = space.kinds.front() == EffectKind::hysteresis;
  const bool slew = space.kinds.front() == EffectKind::slew_limit;
  const auto choose_starts = [&] {
    return (loop && choose_loop_memory(problem, space, z, recordings)) ||
           (slew && choose_drive_at_rest(problem, space, z, recordings));
  };
  choose_starts();
  z = fit_staged(problem, space, z, out.cost);
  if (choose_starts()) z = fit_staged(problem, space, z, out.cost);
  out.z = std::move(z);
  if (loop) out.loop_memory = problem.loop_memory();
  if (slew) out.drive_at_rest = problem.drive_at_rest();
  return out;
}

/// A drift's spline fits the fit segment better than a ramp always (a knot per block): the held-out data
/// choose between the two forms, the ramp unless the spline leaves clearly less there (kSplineGain: on a
/// ramp the two tie within noise, and the spline's many knots would then decide a tie with creep).
constexpr double kSplineGain = 0.05;

size_t drift_form(const std::vector<FitSpace>& spaces, const std::vector<StartFit>& best,
                  const std::vector<std::vector<char>>& held_out, Problem& problem, const std::vector<Series>& data) {
  std::array<double, 2> rmse{};
  for (size_t v = 0; v < 2; ++v) {
    const auto e = spaces[v].effects(best[v].z);
    rmse[v] = errors_of(data, problem.predict(e, spaces[v].g_scale(best[v].z), true).y, held_out).rmse_validation_um;
  }
  return rmse[1] * rmse[1] < (1.0 - kSplineGain) * rmse[0] * rmse[0] ? 1 : 0;
}

/// Fills a candidate from the best fit in each of its spaces (candidate_spaces): parameters, errors, score.
void finish_candidate(CandidateResult& c, const std::vector<FitSpace>& spaces, const std::vector<StartFit>& best,
                      const std::vector<std::vector<char>>& held_out, Problem& problem, const std::vector<Series>& data,
                      const DiagnosisOptions& o) {
  // A loop's second space (spread 0) is the simpler one, taken unless the free spread gains; a saturation's
  // (on the drive) and asymmetric or bias-dependent dynamics' (the slow pole alone) are other forms, taken
  // when they fit better; a drift's spline always fits better, so the held-out data choose it (drift_form).
  const double gain_needed = spaces[0].kinds.front() == EffectKind::hysteresis ? o.hysteresis_shape_min_gain : 0.0;
  const bool drift = spaces[0].kinds.front() == EffectKind::drift;
  const size_t v = spaces.size() < 2 ? 0
                   : drift        ? drift_form(spaces, best, held_out, problem, data)
                                  : (best[0].cost > (1.0 - gain_needed) * best[1].cost ? 1 : 0);
  c.effect = spaces[v].effects(best[v].z).front();
  const Nominal k = spaces[v].g_scale(best[v].z);
  c.time_scale = k.time_scale;
  c.poly_shape = k.shape;
  c.poly_next = k.next;
  c.loop_memory = best[v].loop_memory;
  c.drive_at_rest = best[v].drive_at_rest;
  c.fitted = true;
  problem.use_start_states_of(c);
  const std::vector<Effect> e{c.effect};
  const auto pred = problem.predict(e, nominal_of(c), true);
  if (wanders(e)) c.effect.p[kDriftWander] = std::max(pred.wander_um_per_sqrt_s, 1e-12);
  c.gain = pred.gain;
  c.errors = errors_of(data, pred.y, held_out);
}

/// Whether a loop fitted with G faster than the nuisance refit may make it does no work
/// (DiagnosisOptions::hysteresis_loop_min_share). Fresh seed 127's case035, a parallel 87 Hz mode on a
/// piezo, was called hysteresis so: alpha -1.2e-4 with G 0.65x as fast, the loop's share of the fit 1e-4.
bool loop_idles(const CandidateResult& c, Problem& problem, const std::vector<Series>& data,
                const std::vector<std::vector<char>>& held_out, const DiagnosisOptions& o) {
  if (c.effect.kind != EffectKind::hysteresis || c.time_scale >= time_scale_bounds(o).first) return false;
  std::vector<Effect> without{c.effect};
  without[0].p[0] = 0.0;  // alpha
  const double mse_without = std::pow(errors_of(data, problem.predict(without, nominal_of(c), true).y, held_out).rmse_fit_um, 2);
  return mse_without - std::pow(c.errors.rmse_fit_um, 2) < o.hysteresis_loop_min_share * mse_without;
}

/// The loop's spaces with G's time scale within the nuisance refit's tolerance, and its fits there, started
/// from `best` with the time scale moved into that range.
void refit_loop_at_ordinary_time_scale(CandidateResult& c, std::vector<FitSpace> spaces, const std::vector<StartFit>& best,
                                       const std::vector<std::vector<char>>& held_out, Problem& problem,
                                       const std::vector<Series>& data, const DiagnosisOptions& o) {
  const double lowest = time_scale_bounds(o).first;
  std::vector<StartFit> refits;
  for (size_t v = 0; v < spaces.size(); ++v) {
    spaces[v].specs[spaces[v].specs.size() - kNominalParams].lower = lowest;
    const Eigen::VectorXd& z = best[v].z;
    Nominal k = spaces[v].g_scale(z);
    k.time_scale = std::max(k.time_scale, lowest);
    Eigen::VectorXd s0(z.size());
    s0 << z.head(z.size() - kNominalParams), k.time_scale, k.shape, k.next;
    refits.push_back(fit_from(spaces[v], s0, problem, data.size()));
  }
  finish_candidate(c, spaces, refits, held_out, problem, data, o);
}

}  // namespace

/// Fits `candidates[i]` for every i in `which` from starts[i]: every (candidate, space, start) is a
/// task of its own (a loop's eight fits cost as much as the other candidates together, so whole candidates
/// balanced badly over threads), the loop's first. Each task starts from `problem`'s loop memory, so the
/// result does not depend on the order or the threads.
void fit_each(std::string_view stage, std::vector<CandidateResult>& candidates, const std::vector<size_t>& which,
              const Starts& starts, const std::vector<std::vector<char>>& held_out, Problem& problem,
              const std::vector<Series>& data, const DataScale& scale, const DiagnosisOptions& o) {
  struct Task {
    size_t candidate, space, start;
  };
  std::vector<std::vector<FitSpace>> spaces;
  std::vector<Task> tasks;
  for (size_t w = 0; w < which.size(); ++w) {
    spaces.push_back(candidate_spaces(candidates[which[w]].effect.kind, scale, o, data, problem.model().G));
    for (size_t v = 0; v < spaces.back().size(); ++v)
      for (size_t i = 0; i < starts[which[w]].size(); ++i) tasks.push_back({w, v, i});
  }
  std::stable_partition(tasks.begin(), tasks.end(), [&](const Task& t) { return spaces[t.candidate].size() > 1; });
  std::vector<StartFit> fits(tasks.size());
  run_each(stage, tasks.size(), problem, o, [&](size_t i, Problem& own) {
    const Task& t = tasks[i];
    fits[i] = fit_from(spaces[t.candidate][t.space], starts[which[t.candidate]][t.start], own, data.size());
  });
  std::vector<std::vector<StartFit>> best(which.size());
  for (size_t w = 0; w < which.size(); ++w) best[w].resize(spaces[w].size());
  for (size_t i = 0; i < tasks.size(); ++i) {  // the first start wins ties
    auto& b = best[tasks[i].candidate][tasks[i].space];
    if (b.z.size() == 0 || fits[i].cost < b.cost) b = std::move(fits[i]);
  }
  for (size_t w = 0; w < which.size(); ++w) {
    finish_candidate(candidates[which[w]], spaces[w], best[w], held_out, problem, data, o);
    if (loop_idles(candidates[which[w]], problem, data, held_out, o))
      refit_loop_at_ordinary_time_scale(candidates[which[w]], spaces[w], best[w], held_out, problem, data, o);
    candidates[which[w]].unobserved = unobserved_by(candidates[which[w]].effect, scale);
  }
}

std::string unobserved_by(const Effect& e, const DataScale& scale) {
  if (e.kind != EffectKind::dead_zone || !(e.p[0] * kThresholdReach < scale.u_abs_nearest_V())) return {};
  return format("its threshold (%.3g V) lies below a tenth of the smallest recorded |command| (%.3g V): the recordings "
                "never come near it, and its catch-up alone is a corner in the static curve that other effects make too",
                e.p[0], scale.u_abs_nearest_V());
}

/// Whether the fitting segment separates candidates `a` and `b` that the held-out data cannot: `a`
/// explains it clearly better, by `share` of what `b` leaves there and by the ambiguity margin of what the
/// nuisance-only refit leaves there (two fits at the noise floor differ by noise).
bool fit_segment_prefers(const CandidateResult& a, const CandidateResult& b, const DiagnosisResult& res,
                         const DiagnosisOptions& o, double share) {
  const double s2 = res.noise_sigma_um * res.noise_sigma_um;
  const auto fit_excess = [&](const ModelErrors& e) { return e.rmse_fit_um * e.rmse_fit_um - s2; };
  const double gain = fit_excess(b.errors) - fit_excess(a.errors);
  return gain > share * fit_excess(b.errors) && gain > o.ambiguity_margin * fit_excess(res.nominal_refit.errors);
}

namespace {

/// When the held-out data cannot separate the two best (their held-out excess within the ambiguity margin
/// of the nuisance-only excess: a mode that the held-out stretch hardly excites and a creep that reproduces
/// its low-frequency gain), the one that explains the fitting segment clearly better leads.
void break_tie(DiagnosisResult& res, const DiagnosisOptions& o) {
  if (res.candidates.size() < 2 || !res.candidates[1].nameable()) return;
  const Excess excess(res);
  const auto& a = res.candidates[0];
  const auto& b = res.candidates[1];
  if (excess.ties(a.errors, b.errors, o) && fit_segment_prefers(b, a, res, o, o.tie_fit_gain))
    std::swap(res.candidates[0], res.candidates[1]);
}

/// Puts first the best-ranked candidate that explains the excess (o.explained_excess) when the best-ranked one
/// does not. The score's penalty per parameter is a share of the whole MSE, the noise included: at the noise
/// floor it can rank a one-parameter candidate that explains nothing above a richer one that explains most of
/// the excess (a tuning case of bias-dependent dynamics in closed loop: a delay leaving all of it ranked above
/// the dynamics leaving a fifth), and the verdict was then `unexplained`.
void lead_with_an_explanation(DiagnosisResult& res, const Excess& excess, const DiagnosisOptions& o) {
  const auto explains = [&](const CandidateResult& c) { return c.nameable() && excess.explained_by(c.errors, o); };
  if (res.candidates.empty() || explains(res.candidates.front())) return;
  const auto it = std::find_if(res.candidates.begin(), res.candidates.end(), explains);
  if (it != res.candidates.end()) std::rotate(res.candidates.begin(), it, std::next(it));
}

}  // namespace

/// Fitted candidates by penalised score on the judging segment (Excess: held-out unless it carries no
/// excess), then the rest by evidence; ties broken on the fit segment; a candidate that explains the excess
/// ahead of those that do not (lead_with_an_explanation).
void rank_candidates(DiagnosisResult& res, const DiagnosisOptions& o) {
  const Excess excess(res);
  for (auto& c : res.candidates)
    if (c.fitted) c.score = excess.score(c.errors, c.specs.size() - unpenalised_parameters({&c.effect, 1}), o);
  // Fitted and observed, then fitted but unobserved, then the rest.
  const auto tier = [](const CandidateResult& c) { return c.nameable() ? 0 : (c.fitted ? 1 : 2); };
  std::stable_sort(res.candidates.begin(), res.candidates.end(), [&](const CandidateResult& a, const CandidateResult& b) {
    if (tier(a) != tier(b)) return tier(a) < tier(b);
    return a.fitted ? a.score < b.score : a.evidence_r2 > b.evidence_r2;
  });
  break_tie(res, o);
  lead_with_an_explanation(res, excess, o);
}

/// Every candidate's evidence and starts (the grid's, or `warm`'s fits), then the full fit of the leading
/// ones by evidence, ranked by held-out score.
void fit_candidates(DiagnosisResult& res, Problem& problem, const std::vector<Series>& data, const DataScale& scale,
                    const DiagnosisOptions& o, double nuisance_cost, WarmStarts warm) {
  const Starts starts = !warm.candidates       ? grid_starts(res, problem, data, scale, o, nuisance_cost)
                        : warm.regridded == 0 ? warm_starts(res, *warm.candidates, data, scale, o)
                                              : regridded_warm_starts(res, problem, warm, data, scale, o, nuisance_cost);
  std::vector<size_t> order(res.candidates.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return res.candidates[a].evidence_r2 > res.candidates[b].evidence_r2; });
  order.resize(std::min(order.size(), static_cast<size_t>(std::max(o.candidates_to_fit, 0))));
  fit_each(warm.candidates ? warm.stage : "candidate fits", res.candidates, order, starts, res.held_out, problem, data,
           scale, o);
  // What the loop's and the slew limit's fits chose stays for the fits that follow (pairs with them).
  for (size_t i : order) problem.use_start_states_of(res.candidates[i]);
  rank_candidates(res, o);
}

}  // namespace pvcgel::control::diagnosis::detail
