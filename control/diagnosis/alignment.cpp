#include "control/diagnosis/alignment.hpp"

#include <boost/math/tools/minima.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "control/diagnosis/candidates.hpp"
#include "control/diagnosis/significance.hpp"
#include "control/text_format.hpp"

namespace pvcgel::control::diagnosis::detail {

namespace {

/// Fit error of each recording over its first `samples` for the nominal model refitted as `refit`, from the
/// starts in force.
std::vector<double> start_errors(Problem& p, const std::vector<Series>& data, const std::vector<size_t>& samples,
                                 Nominal refit) {
  const auto pred = p.predict({}, refit, true, false);
  std::vector<double> out;
  for (size_t r = 0; r < data.size(); ++r) {
    double e = 0.0;
    for (size_t k = 0; k < std::min(pred.y[r].size(), samples[r]); ++k) e += std::pow(data[r].y_um[k] - pred.y[r][k], 2);
    out.push_back(e);
  }
  return out;
}

/// The rest voltage each recording starts from: u[0], or the one its first samples imply, whichever the
/// nominal model fits better (the modes absorb the rest of G's transient). Leaves `p` set to it.
void choose_start_states(Problem& p, const std::vector<Series>& data) {
  std::vector<double> at_u0;
  for (const auto& s : data) at_u0.push_back(s.u_V.front());
  p.set_initial(at_u0);
  const auto pa = p.predict({}, 1.0, true, false);
  p.set_initial(std::vector<double>(data.size(), NAN));
  const auto pb = p.predict({}, 1.0, true, false);
  std::vector<double> chosen;
  for (size_t r = 0; r < data.size(); ++r) {
    double ea = 0.0, eb = 0.0;
    for (size_t k = 0; k < pa.y[r].size(); ++k)
      ea += std::pow(data[r].y_um[k] - pa.y[r][k], 2), eb += std::pow(data[r].y_um[k] - pb.y[r][k], 2);
    chosen.push_back(ea <= eb ? data[r].u_V.front() : NAN);
  }
  p.set_initial(chosen);
}

/// The relative difference of two fit errors below which they are one: the resolution of a fit error
/// that the nominal model's own error dominates.
constexpr double kFlatMse = 1e-3;

/// The I/O delay estimate, sub-sample, and the whole samples the analysis uses.
struct DelayEstimate {
  double samples = 0.0;
  int used = 0;
  bool tie_lowered = false;  ///< the best whole delay fitted within kFlatMse of one less: the smaller is used
  std::vector<double> sse_um2;  ///< the fit's squared error (over the fitted samples) at each whole delay searched
};

/// The I/O delay that fits best over 0..max_d samples, jointly with the nuisance refit of the nominal model
/// at every delay (a G a few percent too slow or too fast looks like a sample of delay, and a delay
/// estimated without the refit leaves that sample to be blamed on a `delay` effect later), refined
/// sub-sample by a parabola through the fit error when it has a clearly curved minimum. The whole delay
/// used is the best one, or one less when that fits within kFlatMse of it: a sample of delay needs evidence
/// (the Cascaded Tanks, whose pump voltage is held with no further delay, fitted 0 and 1 sample within
/// 0.07% when its short recordings were held out in three stretches), and `leading_delay` still tries the
/// other with the leading candidates.
DelayEstimate search_delay(Problem& p, int max_d, const DiagnosisOptions& o) {
  DelayEstimate e;
  auto& sse = e.sse_um2;
  sse.resize(static_cast<size_t>(max_d) + 1);
  run_each("delay search", sse.size(), p, o, [&](size_t d, Problem& own) {
    own.set_delay(static_cast<double>(d));
    sse[d] = own.residual({}, refit_nominal(own, o)).squaredNorm();
  });
  const auto best = static_cast<size_t>(std::min_element(sse.begin(), sse.end()) - sse.begin());
  e.samples = static_cast<double>(best);
  e.used = static_cast<int>(best);
  if (best > 0 && sse[best - 1] <= (1.0 + kFlatMse) * sse[best]) e.used = static_cast<int>(best) - 1, e.tie_lowered = true;
  if (best == 0 || best == sse.size() - 1) return e;
  const double m0 = sse[best - 1], m1 = sse[best], m2 = sse[best + 1];
  const double curv = m0 - 2.0 * m1 + m2;
  if (curv > kFlatMse * m1) e.samples += std::clamp(0.5 * (m0 - m2) / curv, -0.5, 0.5);
  return e;
}

/// What the alignment says about the model file's delay: a contradiction of the declared value, or the
/// estimate the analysis uses when the file is silent.
std::string alignment_note(const Alignment& a, int max_d, bool tie_lowered) {
  if (!a.declared)
    return "the model file does not declare io_delay_samples: estimated " + format("%.2g", a.io_delay_samples) +
           " samples from the data (searched 0.." + std::to_string(max_d) + "); " + format("%.0f", a.used_samples) + " used" +
           (tie_lowered ? " (it fits within 0.1% of " + format("%.0f", a.used_samples + 1) + ": a sample of delay needs evidence)" : "");
  if (std::abs(a.io_delay_samples - *a.declared) < 0.5) return "";
  const std::string note = "the model file declares io_delay_samples = " + std::to_string(*a.declared) +
                           ", but the data fit best with " + format("%.2g", a.io_delay_samples) + " samples";
  // Less delay than declared cannot be an effect, but the nominal model alone is drawn below the true
  // delay by a mode's fast path or a creep: the analysis starts at the declared delay, and the leading
  // candidates move it to the estimate only when they fit clearly better there (`leading_delay`).
  if (a.io_delay_samples < *a.declared)
    return note + " (less than declared: the analysis starts at the declared delay and checks the estimate with "
                  "the leading candidates)";
  return note + " (the excess is judged as a delay effect)";
}

/// The delays `leading_delay` tries: the neighbours of the one in use, the declared one and the nominal
/// model's estimate, up to the declared delay (more is a `delay` effect), any up to the search range when the
/// file is silent.
std::vector<int> delays_to_try(const Alignment& a, const DiagnosisOptions& o) {
  const int used = static_cast<int>(std::lround(a.used_samples));
  const int most = a.declared ? *a.declared : o.max_undeclared_delay_samples;
  std::vector<int> delays;
  for (int d : {used - 1, used + 1, a.declared.value_or(used), static_cast<int>(std::lround(a.io_delay_samples))})
    if (d >= 0 && d <= most && d != used && std::find(delays.begin(), delays.end(), d) == delays.end()) delays.push_back(d);
  return delays;
}

}  // namespace

/// Refines each recording's rest voltage before its first sample (the problem's starts: u[0], or NaN for
/// the voltage its first samples imply) by Brent's search on its fit error over its first window,
/// for the nominal model refitted as `k`; kept only where it fits clearly better. Returns whether any moved.
/// Neither guess is the rest in closed loop: the controller's first command carries its gain times the first
/// error, and the first samples' level carries the sensor offset; the samples before the delayed first
/// command then come from the wrong voltage.
bool refine_starts(Problem& p, const std::vector<Series>& data, const DiagnosisOptions& o, Nominal k) {
  auto starts = p.initial();
  bool refined = false;
  // The first window only: over the whole recording the start trades for a slow effect (a drift, a creep).
  std::vector<size_t> window;
  for (const auto& s : data) window.push_back(std::min(window_samples(s, o), s.y_um.size()));
  const auto error_at = [&](size_t r, double v) {
    auto trial = starts;
    trial[r] = v;
    p.set_initial(trial);
    return start_errors(p, data, window, k)[r];
  };
  constexpr int kBits = 24, kMaxIterations = 40;
  const auto level = window_level(data, o);
  for (size_t r = 0; r < data.size(); ++r) {
    const auto range = voltage_range(data[r]);
    const auto [lo, hi] = range;
    const double reach = 0.25 * std::max(hi - lo, 1e-6 * std::max(std::abs(hi), 1.0));
    // The voltage the first samples imply (NaN) follows the model each simulation runs; a refined start is
    // held fixed, so it replaces that only when it fits clearly better.
    double from = starts[r];
    if (std::isnan(from)) {
      AugmentedPlant plant(p.model(), p.delay(), data[r].sample_time_s, std::span<const Effect>{});
      from = rest_from_output(plant, data[r], range);
    }
    std::uintmax_t iterations = kMaxIterations;
    const auto [best_V, best_error] = boost::math::tools::brent_find_minima(
        [&](double v) { return error_at(r, v); }, from - reach, from + reach, kBits, iterations);
    // Kept only when the first window fits clearly better (kClearlyBetterNoiseVariances; where the start hardly
    // matters, a dead zone about it or a start at rest, the search fits the noise) and the start alone then
    // explains it (within the `none` test's `WindowLevel`): beside an effect the start trades for it
    // (a large creep's onset), and held fixed it would spoil the effect's fit.
    const double variance = std::pow(estimate_noise_sigma(data[r].y_um), 2), n = static_cast<double>(window[r]);
    const bool explained = best_error <= n * variance * level.threshold(n, o);
    if (explained && best_error < error_at(r, starts[r]) - kClearlyBetterNoiseVariances * variance)
      starts[r] = best_V, refined = true;
  }
  p.set_initial(starts);
  return refined;
}

/// Alignment: the start states (choose_start_states), then the I/O delay over 0..max (an undeclared delay)
/// or 0..declared + 2 (to check the file). Leaves `p` set to what the analysis uses.
Alignment estimate_alignment(Problem& p, const std::vector<Series>& data, const DiagnosisOptions& o) {
  Alignment a;
  if (o.io_delay_declared) a.declared = o.io_delay_samples;
  p.set_delay(o.io_delay_samples);
  choose_start_states(p, data);
  const int max_d = o.io_delay_declared ? std::min(o.io_delay_samples + 2, 8) : o.max_undeclared_delay_samples;
  const auto delay = search_delay(p, max_d, o);
  a.io_delay_samples = delay.samples;
  // The analysis runs with whole samples (what a model file and the daemon can hold); the sub-sample
  // estimate is reported.
  a.used_samples = o.io_delay_declared ? o.io_delay_samples : delay.used;
  if (o.io_delay_declared && a.io_delay_samples >= o.io_delay_samples + 0.5) {
    const auto longer = delay.sse_um2.begin() + o.io_delay_samples + 1;
    const auto best = std::min_element(longer, delay.sse_um2.end());
    a.longer_delay = Alignment::LongerDelay{static_cast<int>(best - delay.sse_um2.begin()), *best};
  }
  a.note = alignment_note(a, max_d, !o.io_delay_declared && delay.tie_lowered);
  p.set_delay(a.used_samples);
  a.initial_V = p.initial();
  return a;
}

/// The second pass's alignment: the first pass's estimates, with the delay one of its leading candidates fits
/// clearly better with.
Alignment realign(Problem& p, Alignment a, int delay_samples, const std::string& leader) {
  a.note = (a.declared ? "the model file declares io_delay_samples = " + std::to_string(*a.declared)
                       : std::string("the model file does not declare io_delay_samples")) +
           "; the nominal model alone fits best with " + format("%.2g", a.io_delay_samples) + " samples, but fitted with " +
           "a leading candidate (" + leader + ") the data take " + std::to_string(delay_samples) +
           ", which the analysis uses (an unmodelled effect pulls the nominal model's delay)";
  a.used_samples = delay_samples;
  if (a.declared != delay_samples) a.longer_delay.reset();  // the evidence is against the declared delay
  p.set_delay(a.used_samples);
  p.set_initial(a.initial_V);
  return a;
}

/// The delay was estimated with the nominal model alone, which an unmodelled effect can pull off by a
/// sample (on a closed-loop rig with one sample of delay and a creep, the nominal fits best with none; a
/// mode's fast path draws it below the declared delay). So the two leading candidates are refitted at the
/// other delays the file allows (`delays_to_try`): the runner-up too, because the leader is ranked at the
/// wrong delay (a creep led a mode that way). Returns the delay one of them fits the fit segment clearly
/// better with than the better of the two does at the delay in use, if any: by a quarter of the excess it
/// leaves (the tie rule's share) and by a tenth of the noise variance (far above the spread between two fits
/// at the noise floor).
std::optional<DelayChoice> leading_delay(const DiagnosisResult& res, Problem& problem, const std::vector<Series>& data,
                                         const DataScale& scale, const DiagnosisOptions& o) {
  constexpr size_t kLeading = 2;
  std::vector<const CandidateResult*> leading;
  for (const auto& c : res.candidates)
    if (c.fitted && c.effect.kind != EffectKind::delay && leading.size() < kLeading) leading.push_back(&c);
  const auto delays = delays_to_try(res.alignment, o);
  if (leading.empty() || delays.empty()) return {};
  double at_used = INFINITY;
  for (const auto* c : leading) at_used = std::min(at_used, fit_mse(problem, std::span(&c->effect, 1), nominal_of(*c)));
  std::vector<double> mse(leading.size() * delays.size());
  run_each("leading candidates at other delays", mse.size(), problem, o, [&](size_t i, Problem& own) {
    const auto& c = *leading[i / delays.size()];
    FitSpace space({c.effect.kind}, scale, true, o, &data);
    hold_form_of(space, c.effect);
    own.set_delay(delays[i % delays.size()]);
    double cost = 0.0;
    const auto z = fit_staged(own, space, space.z_of({c.effect}, nominal_of(c)), cost);
    mse[i] = fit_mse(own, space.effects(z), space.g_scale(z));
  });
  const double s2 = res.noise_sigma_um * res.noise_sigma_um;
  double best = at_used;
  std::optional<DelayChoice> better;
  for (size_t i = 0; i < mse.size(); ++i) {
    const double gain = at_used - mse[i];
    if (mse[i] < best && gain > o.tie_fit_gain * (at_used - s2) && gain > o.ambiguity_margin * s2)
      best = mse[i], better = DelayChoice{delays[i % delays.size()], std::string(to_string(leading[i / delays.size()]->effect.kind))};
  }
  return better;
}

}  // namespace pvcgel::control::diagnosis::detail
