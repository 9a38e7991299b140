#include "control/diagnosis/diagnosis.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <utility>

#include "control/config_error.hpp"
#include "control/diagnosis/alignment.hpp"
#include "control/diagnosis/candidates.hpp"
#include "control/diagnosis/fit_problem.hpp"
#include "control/diagnosis/significance.hpp"
#include "control/diagnosis/verdict.hpp"
#include "control/text_format.hpp"

namespace pvcgel::control::diagnosis {

using namespace detail;  // NOLINT: the pipeline below is written in the internal stages' terms

namespace {

/// How held_out_mask cuts an n-sample recording: every block's end, 30% of each third, or its end.
struct HeldOutLayout {
  enum Shape { kBlocks, kThirds, kTail } shape = kBlocks;
  size_t block = 0;   ///< samples per block (kBlocks, kTail); the block it is shorter than two of (kThirds)
  size_t fitted = 0;  ///< a block's first samples, fitted (kBlocks, kTail)
};

HeldOutLayout held_out_layout(size_t n, double Ts, const DiagnosisOptions& o) {
  // A block of at least kMinValidationBlockSamples: on a slow rig (a water tank sampled every 4 s) a 10 s
  // block held out every third sample, each between two fitted neighbours, which tests interpolation.
  const auto block = std::max(static_cast<size_t>(std::lround(o.validation_block_s / Ts)), kMinValidationBlockSamples);
  const auto fitted = [&](size_t b) {
    return static_cast<size_t>(std::lround((1.0 - o.validation_fraction) * static_cast<double>(b)));
  };
  if (n >= 2 * block) return {HeldOutLayout::kBlocks, block, fitted(block)};
  if (n >= 3 * kMinValidationBlockSamples) return {HeldOutLayout::kThirds, block, 0};
  return {HeldOutLayout::kTail, n, fitted(n)};
}

}  // namespace

std::vector<char> held_out_mask(size_t n, double Ts, const DiagnosisOptions& o) {
  const HeldOutLayout layout = held_out_layout(n, Ts, o);
  std::vector<char> mask(n, 0);
  if (layout.shape == HeldOutLayout::kThirds) {
    // A short recording: held out at its end, a chirp's highest frequencies or a step's late creep were never
    // fitted (a 10 kHz chirp's slew limit acted there alone). So 30% of each third, at the first third's end
    // (the start is fitted), the second's middle and the last's start: neither end is held out.
    const size_t third = n / 3;
    const auto held = static_cast<size_t>(std::lround(o.validation_fraction * static_cast<double>(third)));
    for (size_t at : {third - held, third + (third - held) / 2, 2 * third})
      std::fill_n(mask.begin() + static_cast<std::ptrdiff_t>(at), held, 1);
    return mask;
  }
  // Under 300 samples (kTail) the recording is one block.
  for (size_t k = 0; k < n; ++k) mask[k] = (k % layout.block) >= layout.fitted ? 1 : 0;
  return mask;
}

std::string held_out_rule(size_t n, double Ts, const DiagnosisOptions& o) {
  const HeldOutLayout layout = held_out_layout(n, Ts, o);
  const double percent = 100.0 * o.validation_fraction;
  if (layout.shape == HeldOutLayout::kTail) return format("the last %g%% (a recording under %zu samples)", percent, 3 * kMinValidationBlockSamples);
  const size_t held = layout.block - layout.fitted;
  const double block_s = static_cast<double>(layout.block) * Ts;
  const std::string block = block_s >= 1.0 ? format("%g s", block_s) : format("%zu samples", layout.block);
  if (layout.shape == HeldOutLayout::kThirds)
    return format("%g%% of each third, neither end (shorter than two blocks of %s)", percent, block.c_str());
  if (block_s >= 1.0) return format("the last %g s of every %s block", static_cast<double>(held) * Ts, block.c_str());
  return format("the last %zu of every %zu samples", held, layout.block);
}

namespace {

/// Direction reversals of u over [b, e) by more than `band`, so noise on u (closed loop) does not count.
long reversals_of(const Series& s, size_t b, size_t e, double band) {
  long reversals = 0;
  int dir = 0;
  double anchor = s.u_V[b];
  for (size_t k = b; k < e; ++k) {
    const double u = s.u_V[k];
    if (u > anchor + band || u < anchor - band) {
      const int now = u > anchor ? 1 : -1;
      reversals += dir == -now;
      dir = now;
      anchor = u;
    } else if ((dir > 0 && u > anchor) || (dir < 0 && u < anchor)) {
      anchor = u;
    }
  }
  return reversals;
}

}  // namespace

std::string describe_regime(const Series& s, size_t b, size_t e) {
  if (e <= b) return "";
  // Scaled by the recording: an amplifier's 0-10 V input or a piezo's +-0.15 V reads as well as a kilovolt.
  const auto [all_lo, all_hi] = std::minmax_element(s.u_V.begin(), s.u_V.end());
  const double u_abs = std::max(std::abs(*all_lo), std::abs(*all_hi));
  const int decimals = std::clamp(2 - static_cast<int>(std::floor(std::log10(std::max(*all_hi - *all_lo, 1e-300)))), 0, 9);
  const auto volts = [&](double v) {  // no "-0.000" for a mean that rounds to zero
    return format("%.*f", decimals, std::abs(v) < 0.5 * std::pow(10.0, -decimals) ? 0.0 : v);
  };
  const auto first = s.u_V.begin() + static_cast<std::ptrdiff_t>(b), last = s.u_V.begin() + static_cast<std::ptrdiff_t>(e);
  const auto [lo, hi] = std::minmax_element(first, last);
  long rising = 0, falling = 0;
  for (size_t k = b + 1; k < e; ++k) {
    rising += s.u_V[k] > s.u_V[k - 1];
    falling += s.u_V[k] < s.u_V[k - 1];
  }
  std::string r = "u " + volts(*lo) + ".." + volts(*hi) + " V (mean " + volts(std::accumulate(first, last, 0.0) / static_cast<double>(e - b)) +
                  " V, amplitude " + volts((*hi - *lo) / 2) + " V)";
  // Under 0.25% of the largest |u| (1 V of 400 V) a window is held: what moves it is noise on u.
  if (rising + falling == 0 || *hi - *lo < 0.0025 * u_abs) return r + ", held";
  r += ", rising " + format("%.0f", 100.0 * static_cast<double>(rising) / static_cast<double>(rising + falling)) + "% of moving samples";
  const long reversals = reversals_of(s, b, e, std::max(0.1 * (*hi - *lo), 0.0025 * u_abs));
  const double f = static_cast<double>(reversals) / (2.0 * static_cast<double>(e - b) * s.sample_time_s);
  return r + (reversals > 0 ? ", ~" + format("%.2g", f) + " Hz" : (rising > falling ? ", rising ramp/step" : ", falling ramp/step"));
}

void check_series(const Series& s, const HammersteinModel& model) {
  const size_t n = s.t_s.size();
  if (s.u_V.size() != n || s.y_um.size() != n) throw std::invalid_argument("t_s, u_V and y_um differ in length");
  if (n < 3) throw std::invalid_argument("fewer than 3 samples");
  const double Ts = s.sample_time_s;
  for (size_t k = 0; k < n; ++k) {
    if (!std::isfinite(s.t_s[k]) || !std::isfinite(s.u_V[k]) || !std::isfinite(s.y_um[k]))
      throw std::invalid_argument("sample " + std::to_string(k) + ": non-finite t_s, u_V or y_um");
    if (k > 0) {
      const double dt = s.t_s[k] - s.t_s[k - 1];
      if (!(dt > 0)) throw std::invalid_argument("sample " + std::to_string(k) + ": time does not increase");
      if (std::abs(dt - Ts) > 0.01 * Ts)
        throw std::invalid_argument("sample " + std::to_string(k) + ": non-uniform sampling (step " +
                                    format("%.6g", dt) + " s, expected " + format("%.6g", Ts) + " s)");
    }
  }
  const double slowest = model.G.slowest_time_constant_s();
  const double dur = static_cast<double>(n - 1) * Ts;
  // The start state is fitted (G's free-response modes), so a recording need not outlast the start-up
  // transient several times; shorter than one time constant, the start cannot be told from the response.
  if (dur < slowest)
    throw std::invalid_argument("recording lasts " + format("%.3g", dur) + " s, shorter than one time constant of G's slowest pole (" +
                                format("%.3g", slowest) + " s): the start state cannot be told from the response");
}

std::vector<std::vector<double>> simulate(const HammersteinModel& model, const Effect& effect,
                                          const std::vector<Series>& data, int io) {
  std::vector<std::vector<double>> out;
  for (const auto& s : data) {
    AugmentedPlant plant(model, io, s.sample_time_s, effect);
    out.push_back(plant.simulate(s.u_V, rest_from_output(plant, s)));
  }
  return out;
}

HammersteinModel refit_model(const HammersteinModel& model, double time_scale, double poly_shape, double poly_next) {
  HammersteinModel m = model;
  if (time_scale != 1.0) m.G = time_scaled(model.G, time_scale);
  if (poly_shape != 1.0 || poly_next != 0.0) {
    auto c = model.f.coefficients();
    for (size_t i = 1; i < c.size(); ++i) c[i] *= poly_shape;
    if (poly_next != 0.0 && c.size() < static_cast<size_t>(OddPolynomial::kMaxTerms)) c.push_back(poly_next);
    m.f = OddPolynomial(c);
  }
  return m;
}

TransferFunction time_scaled(const TransferFunction& G, double factor) {
  // G(factor s): the coefficient of s^i is multiplied by factor^i.
  const auto scale = [&](std::vector<double> c) {
    for (size_t i = 0; i < c.size(); ++i) c[i] *= std::pow(factor, static_cast<double>(c.size() - 1 - i));
    return c;
  };
  return TransferFunction(scale(G.num()), scale(G.den()));
}

namespace {

/// Localisation: windows whose residual RMS exceeds `ratio` times the noise, merged into mismatch windows.
void locate(DiagnosisResult& res, const std::vector<Series>& data, double sigma, double ratio, const DiagnosisOptions& o) {
  res.mismatch.clear();  // a refit made again (none_from_leader) locates again
  res.window_centre_s.clear();
  res.window_rms_um.clear();
  res.window_recording.clear();
  for (size_t r = 0; r < data.size(); ++r) {
    const auto& s = data[r];
    const size_t w = window_samples(s, o);
    MismatchWindow open;
    SquaredError open_err;
    bool is_open = false;
    size_t open_begin = 0;
    auto close = [&](size_t end) {
      open.t_end_s = s.t_s[end - 1] + s.sample_time_s;
      open.rms_um = std::sqrt(open_err.mse());
      open.regime = describe_regime(s, open_begin, end);
      res.mismatch.push_back(open);
      is_open = false;
    };
    for (size_t b = 0; b < s.u_V.size(); b += w) {
      const size_t e = std::min(b + w, s.u_V.size());
      if (e - b < w / 2) break;
      SquaredError err;
      for (size_t k = b; k < e; ++k) err.add(s.y_um[k] - res.y_baseline_um[r][k]);
      const double rms = std::sqrt(err.mse());
      res.window_centre_s.push_back(0.5 * (s.t_s[b] + s.t_s[e - 1]));
      res.window_rms_um.push_back(rms);
      res.window_recording.push_back(static_cast<int>(r));
      if (rms > ratio * sigma) {
        if (!is_open) {
          open = MismatchWindow{static_cast<int>(r), s.t_s[b], 0.0, "", 0.0};
          open_err = {};
          open_begin = b;
          is_open = true;
        }
        open_err.sum += err.sum;
        open_err.n += err.n;
      } else if (is_open) {
        close(b);
      }
    }
    if (is_open) close(s.u_V.size());
  }
}

/// Bad input stops before any analysis: no recordings, an unstable G, a bad series, an f that turns over
/// inside the recorded voltages.
void check_inputs(const HammersteinModel& model, const std::vector<Series>& data) {
  if (data.empty()) throw std::invalid_argument("no recordings");
  if (!model.G.is_stable()) throw ConfigError("model.G", "G(s) = " + model.G.to_string() + " is unstable");
  double u_max = 0.0;
  for (const auto& s : data) {
    check_series(s, model);
    for (double u : s.u_V) u_max = std::max(u_max, std::abs(u));
  }
  if (const auto turn = model.f.first_turnover(std::max(u_max, 1e-9)))
    throw ConfigError("model.poly", "f is not monotone: f'(x) reaches 0 at x = " + format("%.4g", *turn) +
                                        " V, inside the recorded voltage range (|u| up to " + format("%.4g", u_max) + " V)");
}

/// 1. Alignment (nuisance): start state, I/O delay, offset. The baseline is the model as the file states it
/// (with the estimated delay when the file is silent); `aligned` adds the sensor offset and start state,
/// which are not the model's fault. Returns the scale of the data (for the candidates' ranges).
DataScale align_and_baseline(DiagnosisResult& res, Problem& problem, const std::vector<Series>& data,
                             const DiagnosisOptions& o, const std::optional<SecondPass>& second) {
  res.alignment = second ? realign(problem, second->alignment, second->delay_samples, second->leader)
                         : estimate_alignment(problem, data, o);
  const auto base = problem.predict({}, 1.0, false);
  res.y_baseline_um = problem.raw({}, 1.0, true);
  res.baseline = errors_of(data, res.y_baseline_um, res.held_out);
  res.aligned = errors_of(data, base.y, res.held_out);
  res.alignment.offset_um = base.offset_um;
  res.fitted = res.baseline;
  res.y_fitted_um = res.y_baseline_um;
  return data_scale(data, base.y, res.held_out);
}

/// The nuisance-only refit `k` into res: its parameters, errors, the noise estimated from its residual, the
/// `none` test on it and the mismatch windows. Returns its prediction.
Prediction record_refit(DiagnosisResult& res, Problem& problem, const std::vector<Series>& data,
                        const DiagnosisOptions& o, const Nominal& k) {
  res.alignment.initial_V = problem.initial();
  auto refit = problem.predict({}, k, true);
  auto& r = res.nominal_refit;
  r.gain = refit.gain;
  r.time_scale = k.time_scale;
  r.poly_shape = k.shape;
  r.poly_next_slope = k.next;
  r.poly_next = problem.next_coefficient(k.next, k.shape);
  r.errors = errors_of(data, refit.y, res.held_out);
  r.at_bounds = refit_at_bounds(r, o, false);
  r.fit_sse_um2 = problem.fit_sse_um2(refit.y);
  res.noise_sigma_um = noise_sigma(data, refit.y);
  auto& a = res.alignment;
  a.declared_delay_excess_noise_variances =
      a.longer_delay ? std::max(0.0, r.fit_sse_um2 - a.longer_delay->sse_um2) / std::pow(res.noise_sigma_um, 2) : 0.0;
  res.none_test = none_test(data, refit.y, res.noise_sigma_um, o);
  locate(res, data, res.noise_sigma_um, std::sqrt(res.none_test.window_threshold), o);
  return refit;
}

/// 2. Nuisance-only refit of the nominal model (gain, G's time scale, f's shape within tolerance; from the
/// nominal and from `narrow`, the refit at the ordinary tolerances when these are widened), the noise
/// estimated from its residual, 3. the none test on it and the mismatch windows. Returns its prediction.
Prediction refit_and_test(DiagnosisResult& res, Problem& problem, const std::vector<Series>& data, const DiagnosisOptions& o,
                          Nominal& k, std::optional<Nominal> narrow) {
  k = refit_nominal(problem, o, narrow);
  // The starts once more with the refitted model (with the nominal, far off, they trade for its error).
  if (refine_starts(problem, data, o, k)) k = refit_nominal(problem, o, narrow);
  return record_refit(res, problem, data, o, k);
}

}  // namespace

std::vector<std::string> refit_at_bounds(const NominalRefit& r, const DiagnosisOptions& o, bool with_loop) {
  // Within 1% of the way from the nominal to a bound: a least-squares refit that stops there wanted to go further.
  const auto at = [](double v, double lo, double hi, double nominal) {
    return std::abs(v - lo) <= 0.01 * (nominal - lo) || std::abs(hi - v) <= 0.01 * (hi - nominal);
  };
  const auto [t_lo, t] = time_scale_bounds(o, with_loop);
  std::vector<std::string> names;
  const auto [gain_lo, gain_hi] = gain_bounds(o);
  if (at(r.gain, gain_lo, gain_hi, 1.0)) names.emplace_back("gain");
  if (at(r.time_scale, t_lo, t, 1.0)) names.emplace_back("time_scale");
  const auto [shape_lo, shape_hi] = poly_shape_bounds(o);
  if (at(r.poly_shape, shape_lo, shape_hi, 1.0)) names.emplace_back("poly_shape");
  if (at(r.poly_next_slope, -o.poly_next_tolerance, o.poly_next_tolerance, 0.0)) names.emplace_back("poly_next_slope");
  return names;
}

std::pair<double, double> poly_shape_bounds(const DiagnosisOptions& o) {
  const double tol = o.poly_shape_tolerance;
  return {tol < 1.0 ? 1.0 - tol : 1.0 / (1.0 + tol), 1.0 + tol};
}

std::pair<double, double> gain_bounds(const DiagnosisOptions& o) {
  return {1.0 / (1.0 + o.gain_tolerance), 1.0 + o.gain_tolerance};
}

std::pair<double, double> time_scale_bounds(const DiagnosisOptions& o, bool with_loop) {
  const double t = 1.0 + o.time_scale_tolerance;
  return {with_loop ? std::min(o.hysteresis_time_scale_min, 1.0 / t) : 1.0 / t, t};
}

DiagnosisOptions widened_tolerances(DiagnosisOptions o) {
  // 0.25..4: the gain follows f's first term, which a fit of too low an order may double (shape_off).
  o.gain_tolerance = std::max(o.gain_tolerance, 3.0);
  o.poly_shape_tolerance = std::max(o.poly_shape_tolerance, 3.0);
  o.poly_next_tolerance = std::max(o.poly_next_tolerance, 3.0);
  o.f_increasing_margin = std::min(o.f_increasing_margin, 1.05);
  return o;
}

double excess_share_left(const DiagnosisResult& res, const ModelErrors& e) {
  const Excess excess(res);
  return excess.base > 0.0 ? excess(e) / excess.base : NAN;
}

namespace {

/// f's shape or its next term at its tolerance (the gain inside it): the parameters, else none. A nominal f
/// of too low an order (the least-squares n = 2 fit of an n = 3 curve) needs its first term halved and its
/// shape doubled, and the gain then goes with f's first term: so the widened pass decides `none` alone, and
/// when the data are not `none` there, the diagnosis goes on with the ordinary tolerances.
std::vector<std::string> shape_off(const NominalRefit& r) {
  std::vector<std::string> off;
  for (const auto& b : r.at_bounds)
    if (is_f_term(b)) off.push_back(b);
  return off;
}

/// When the nuisance-only refit's gain stops at its tolerance, the nominal's static curve is off by more
/// than a recalibration: its parameters at their tolerance (the gain and f's terms), else none. f's shape
/// alone at its bound widens only the `none` decision (shape_off): there a dead zone or a saturation may be
/// what bends the curve, and on the tuning set, widening the whole diagnosis on it turned an
/// asymmetric-dynamics case into a mode.
std::vector<std::string> static_curve_off(const NominalRefit& r) {
  if (!r.at_bound("gain")) return {};
  auto off = shape_off(r);
  off.insert(off.begin(), "gain");  // refit_at_bounds names the gain first
  return off;
}

}  // namespace

std::vector<std::string> second_effect_shortfalls(const SecondEffectTest& test, std::array<std::string, 2> members) {
  std::vector<std::string> out;
  if (test.named || test.effects.size() != 2) return out;
  for (size_t i = 0; i < 2; ++i)
    if (!test.member[i].significant) out.push_back((members[i].empty() ? test.effects[i] : members[i]) + " not significant");
  if (!test.explained) out.emplace_back("the pair leaves over half the excess");
  if (!test.material) out.emplace_back("not material");
  if (out.empty()) out.emplace_back("withheld");
  if (test.single_at_the_noise()) out.emplace_back("the best single effect alone at the noise");
  return out;
}

std::string_view loop_start_name(double branch) noexcept {
  if (branch == 0.0) return "virgin";
  if (std::abs(branch) < 1.0) return branch > 0.0 ? "partway rising" : "partway falling";
  return branch > 0.0 ? "rising" : "falling";
}

namespace {

/// Each recording's held-out mask and its rule in words.
void hold_out(DiagnosisResult& res, const std::vector<Series>& data, const DiagnosisOptions& o) {
  for (const auto& s : data) {
    res.held_out.push_back(held_out_mask(s.u_V.size(), s.sample_time_s, o));
    res.held_out_rule.push_back(held_out_rule(s.u_V.size(), s.sample_time_s, o));
  }
}

/// A diagnosis's first stages at the tolerances `o`: alignment, the nuisance-only refit, the `none` test.
struct PassStart {
  DiagnosisResult res;
  Problem problem;
  DataScale scale;
  Nominal k;
  Prediction refit;
  bool none = false;
};

/// `narrow`: the nuisance-only refit at the ordinary tolerances, a second start when `o` widens them (a wide
/// refit from the nominal alone can step far into a worse basin: f's shape to its bound, the start state
/// beyond the recorded voltages).
PassStart start_pass(const HammersteinModel& model, const std::vector<Series>& data, const DiagnosisOptions& o,
                     const std::optional<SecondPass>& second, std::optional<Nominal> narrow = std::nullopt) {
  DiagnosisResult res;
  hold_out(res, data, o);
  Problem problem(model, data, res.held_out, o);
  DataScale scale = align_and_baseline(res, problem, data, o, second);
  Nominal k;
  auto refit = refit_and_test(res, problem, data, o, k, narrow);
  cover_model_displacement(scale, refit);
  const bool none = decide_none(res, refit, o);
  return {std::move(res), std::move(problem), scale, k, std::move(refit), none};
}

/// The diagnosis at widened_tolerances, begun: its first stages (start_pass), why it was widened, and the
/// ordinary diagnosis when it ran to the end first (its candidate fits are the wide one's starts, and its
/// answer what the wide one must beat).
struct WideStart {
  std::vector<std::string> from;
  std::optional<PassStart> start;
  const DiagnosisResult* ordinary = nullptr;
};

/// Where a diagnosis_pass stands between runs of its first stages.
struct PassState {
  DiagnosisOptions o;                     // the tolerances in force
  std::vector<std::string> widened_from;  // why `o` is widened; empty at the ordinary tolerances
  bool shape_tried = false;               // the refit with a wider curve ran (or this pass is wide)
  std::optional<SecondPass> second;       // the delay the leading candidate asked for
  std::optional<Nominal> narrow;          // the ordinary pass's refit, once widened
  int earlier_simulations = 0;            // of the runs before the one that decides
};

/// The nominal's static curve is far off (static_curve_off): true when everything must run again, wider.
bool widen_whole_pass(PassState& st, const PassStart& p, const DiagnosisOptions& options) {
  st.widened_from = static_curve_off(p.res.nominal_refit);
  if (st.widened_from.empty()) return false;
  st.o = widened_tolerances(options);
  st.narrow = p.k;
  st.earlier_simulations += p.problem.simulations();
  return true;
}

/// f's shape alone at its bound: a wider f may make the data none (the `none` test once more, f's shape and
/// next term free to widened_tolerances), and then that is the answer. Effects are fitted wider only in a
/// second diagnosis that must predict the held-out data better (a dead zone or a saturation may be what
/// bends the curve): handed to `wider_curve`, begun, when its refit leaves little enough of the excess.
std::optional<DiagnosisResult> try_wider_curve(PassState& st, const PassStart& p, const HammersteinModel& model,
                                               const std::vector<Series>& data, const DiagnosisOptions& options,
                                               WideStart* wider_curve) {
  auto off = shape_off(p.res.nominal_refit);
  if (off.empty()) return std::nullopt;
  auto wide = start_pass(model, data, widened_tolerances(options), std::nullopt, p.k);
  if (wide.none) {
    wide.res.nominal_refit.widened_from = std::move(off);
    wide.res.simulations = st.earlier_simulations + p.problem.simulations() + wide.problem.simulations();
    return std::move(wide.res);
  }
  st.shape_tried = true;
  if (wider_curve && Excess(wide.res).base <= st.o.wider_curve_excess * Excess(p.res).base) {
    wider_curve->from = std::move(off);
    wider_curve->start.emplace(std::move(wide));  // its simulations are the second run's to count
  } else {
    st.earlier_simulations += wide.problem.simulations();
  }
  return std::nullopt;
}

/// The held-out excess MSE a diagnosis's best single effect leaves, as a share of `ordinary`'s nuisance-only
/// refit's (its nuisance-only refit's when no candidate was fitted).
double best_single_left(const DiagnosisResult& r, const DiagnosisResult& ordinary) {
  const Excess excess(ordinary);
  const bool fitted = !r.candidates.empty() && r.candidates.front().fitted;
  return excess(fitted ? r.candidates.front().errors : r.nominal_refit.errors) / excess.base;
}

/// A wide pass, its candidates fitted, whose best single effect does not predict the held-out data better than
/// the ordinary diagnosis's best single effect by the ambiguity margin: it stops before its pairs. On the 240
/// evaluation cases (2026-11-30, d51ac6b) 6 of the 15 wide passes were so, and none of those was kept after
/// its pairs: the pairs, the longest stage, went to waste.
bool wide_cannot_win(const WideStart& widened, const PassStart& p, const DiagnosisOptions& o) {
  return widened.ordinary && o.stop_wide_without_better_single &&
         best_single_left(p.res, *widened.ordinary) >= best_single_left(*widened.ordinary, *widened.ordinary) - o.ambiguity_margin;
}

/// The leader's joint fit may reach a better optimum of the nuisance parameters alone than the nuisance-only
/// refit did from the nominal (fresh seed 163's case010, a `none`: the delay candidate, its delay fitted at 0,
/// reached the noise, 0.050 um, where the nuisance-only refit stopped at 0.078 um). The nuisance-only refit
/// is made again from the leader's nominal as a second start; when it then passes the `none` test, that is
/// the answer (true, res updated), else nothing changes.
bool none_from_leader(PassStart& p, const std::vector<Series>& data, const DiagnosisOptions& o) {
  const auto& leader = p.res.candidates.front();
  if (!leader.fitted) return false;
  // Clamped into the nuisance-only refit's bounds by FitSpace::z_of (a loop's G may be faster than they allow).
  const Nominal k = refit_nominal(p.problem, o, nominal_of(leader));
  DiagnosisResult trial = p.res;  // the alignment, baseline and candidates kept; the refit's part made again
  auto refit = record_refit(trial, p.problem, data, o, k);
  if (!(trial.nominal_refit.errors.rmse_um < p.res.nominal_refit.errors.rmse_um)) return false;
  if (!decide_none(trial, refit, o)) {
    // It passes the `none` test but a longer delay fits clearly better: decide judges that against this refit.
    if (trial.none_test.longer_delay_pending) p.res = std::move(trial), p.k = k;
    return false;
  }
  trial.explanation += "; this nuisance-only refit started from " + std::string(to_string(leader.effect.kind)) +
                       "'s joint fit, a better optimum than the one from the nominal model (residual " +
                       format("%.3g", p.res.nominal_refit.errors.rmse_um) + " um)";
  p.res = std::move(trial);
  p.k = k;
  return true;
}

enum class FitOutcome { at_another_delay, decided, wide_stopped };

/// 4. Candidates, fitted jointly with the nuisance refit; 5. the verdict. at_another_delay, with st.second set,
/// when the leading candidate fits clearly better at another delay: the pass runs once more at that delay.
/// wide_stopped, without a verdict, when a wide pass cannot beat the ordinary one (wide_cannot_win).
FitOutcome fit_and_decide(PassState& st, PassStart& p, const std::vector<Series>& data, const WideStart& widened) {
  const auto* ordinary_fits = widened.ordinary ? &widened.ordinary->candidates : nullptr;
  const WarmStarts warm = st.second ? WarmStarts{&st.second->candidates, "candidate fits at the new delay"}
                                    : WarmStarts{ordinary_fits, "candidate fits from the ordinary run's", kRegriddedLeaders};
  fit_candidates(p.res, p.problem, data, p.scale, st.o, p.res.nominal_refit.fit_sse_um2, warm);
  if (const auto d = st.second ? std::nullopt : leading_delay(p.res, p.problem, data, p.scale, st.o)) {
    st.second = SecondPass{p.res.alignment, p.res.candidates, d->delay_samples, d->candidate};
    st.earlier_simulations += p.problem.simulations();
    return FitOutcome::at_another_delay;
  }
  if (none_from_leader(p, data, st.o)) return FitOutcome::decided;
  if (wide_cannot_win(widened, p, st.o)) return FitOutcome::wide_stopped;
  decide(p.res, p.problem, data, p.scale, st.o);
  return FitOutcome::decided;
}

/// A diagnosis_pass's answer; `decided` false when a wide pass stopped before its verdict (wide_cannot_win).
struct PassOutcome {
  DiagnosisResult res;
  bool decided = true;
};

/// One diagnosis at the tolerances `options` gives, or from the start at widened_tolerances when
/// `widened.from` names why (its first stages already run when `widened.start` holds them). `wider_curve` is
/// set when f's shape alone stopped at its bound and the widened nuisance-only refit, not `none`, leaves at
/// most DiagnosisOptions::wider_curve_excess of the held-out excess the ordinary one leaves: to whom the
/// caller offers a widened diagnosis, begun.
PassOutcome diagnosis_pass(const HammersteinModel& model, const std::vector<Series>& data,
                           const DiagnosisOptions& options, WideStart widened, WideStart* wider_curve) {
  PassState st;
  st.shape_tried = !widened.from.empty();
  st.o = st.shape_tried ? widened_tolerances(options) : options;
  st.widened_from = std::move(widened.from);
  std::optional<PassStart> begun = std::move(widened.start);
  for (;;) {
    PassStart p = begun ? *std::move(begun) : start_pass(model, data, st.o, st.second, st.narrow);
    begun.reset();
    // A refit that passed the `none` test but for a longer delay (longer_delay_pending) is not widened.
    const bool off_nominal = !p.none && !p.res.none_test.longer_delay_pending;
    if (off_nominal && st.o.widen_off_nominal && st.widened_from.empty() && !st.shape_tried) {
      if (widen_whole_pass(st, p, options)) continue;
      if (auto none = try_wider_curve(st, p, model, data, options, wider_curve)) return {std::move(*none)};
    }
    p.res.nominal_refit.widened_from = st.widened_from;
    const auto fit = p.none ? FitOutcome::decided : fit_and_decide(st, p, data, widened);
    if (fit == FitOutcome::at_another_delay) continue;
    p.res.simulations = st.earlier_simulations + p.problem.simulations();
    return {std::move(p.res), fit == FitOutcome::decided};
  }
}

}  // namespace

// The widened nuisance-only refit alone cannot decide it: it also takes in part of a dead zone or a saturation.
bool widened_predicts_better(const DiagnosisResult& ordinary, const DiagnosisResult& wide, const DiagnosisOptions& o) {
  const Excess excess(ordinary);
  // An `unexplained` diagnosis's model is its nuisance-only refit (its `fitted` errors are the nominal's).
  const auto left = [&](const DiagnosisResult& r) { return excess(r.mixture.empty() ? r.nominal_refit.errors : r.fitted); };
  return left(wide) < left(ordinary) - o.ambiguity_margin * excess.base;
}

DiagnosisResult diagnose(const HammersteinModel& model, const std::vector<Series>& data, const DiagnosisOptions& options) {
  check_inputs(model, data);
  WideStart wider_curve;
  DiagnosisResult ordinary = diagnosis_pass(model, data, options, {}, &wider_curve).res;
  if (wider_curve.from.empty()) return ordinary;
  DiagnosisOptions second = options;  // its stages told apart from the first run's
  if (options.progress)
    second.progress = [tell = options.progress](std::string_view stage, std::size_t done, std::size_t total) {
      tell("with a wider curve: " + std::string(stage), done, total);
    };
  wider_curve.ordinary = &ordinary;
  auto [wide, decided] = diagnosis_pass(model, data, second, std::move(wider_curve), nullptr);
  wide.simulations += ordinary.simulations;
  if (!decided || !widened_predicts_better(ordinary, wide, options)) {
    ordinary.simulations = wide.simulations;
    return ordinary;
  }
  return wide;
}

}  // namespace pvcgel::control::diagnosis
