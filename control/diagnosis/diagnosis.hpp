#pragma once
/// @file
/// Sim-to-real mismatch diagnosis: simulate the nominal model from the recorded
/// voltage (output error), locate where and in which regime the residual
/// exceeds the noise, fit candidate effects and choose by held-out error.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "control/effect.hpp"
#include "control/hammerstein_model.hpp"

namespace pvcgel::control::diagnosis {

/// One recording, whatever it came from: y[k] measured at t[k], then u[k]
/// applied and held until t[k+1]. Uniform sampling.
struct Series {
  std::vector<double> t_s, u_V, y_um;
  double sample_time_s = 1e-3;
};

/// The shortest held-out block in samples (100: 30 held out in a row), whatever validation_block_s says: on a
/// rig sampled below 10 Hz a 10 s block would hold out single samples between fitted ones.
inline constexpr size_t kMinValidationBlockSamples = 100;

/// Tuning of the decision rules (defaults are what `pvcgel diagnose` uses).
struct DiagnosisOptions {
  int io_delay_samples = 1;           ///< the model's I/O delay (samples), as `[model] io_delay_samples`
  bool io_delay_declared = true;      ///< false: the model file is silent, io_delay_samples is estimated
  int max_undeclared_delay_samples = 2;  ///< an undeclared I/O delay is searched over 0..this (hold conventions)
  double gain_tolerance = 0.25;       ///< nominal refit: overall gain within [1/(1+tol), 1+tol]
  double time_scale_tolerance = 0.25; ///< nominal refit: G's time constants scaled within [1/(1+tol), 1+tol]
  /// Fits with hysteresis may make G faster, down to this time scale: a nominal identified on data with a
  /// loop has drawn part of it as lag (a slower G), which the loop takes back.
  double hysteresis_time_scale_min = 0.1;
  /// ... granted to a loop that does work: a loop fit with G faster than time_scale_tolerance allows is
  /// refitted within it when setting its alpha to 0 (the rest as fitted) raises the fit-segment MSE by less
  /// than this share of the MSE without the loop; the faster G alone then explains the data.
  double hysteresis_loop_min_share = 0.25;
  /// The loop's free shape (threshold_spread) is kept only when it lowers the fit-segment MSE of the loop
  /// with the earlier shape (spread 0) by this share; below it the two-parameter loop is reported.
  double hysteresis_shape_min_gain = 0.25;
  double poly_shape_tolerance = 0.1;  ///< nominal refit: f's coefficients above the linear one scaled within 1 +- tol
                                      ///< (from 1 on, within [1 / (1 + tol), 1 + tol]: widened_tolerances)
  double poly_next_tolerance = 0.5;   ///< nominal refit: f gains one odd term of the next order whose slope at the
                                      ///< largest recorded |u| is within +- tol of f's mean slope f(u)/u there
  double f_increasing_up_to_V = 0.0;  ///< a negative added f term keeps f increasing up to this voltage (the
                                      ///< controller's range; at least f_increasing_margin times the largest recorded |u|)
  double f_increasing_margin = 2.0;   ///< see f_increasing_up_to_V
  /// When the data are not `none` and the nuisance-only refit's gain stops at its tolerance, the nominal
  /// model's static curve is further off than a recalibration (a nominal identified with another polynomial
  /// order): the diagnosis then runs again with widened_tolerances, so that error is not blamed on an effect.
  /// When only f's shape stops at its tolerance, the widened nuisance-only refit decides `none`: the data are
  /// `none` if they are `none` there. Else, when that refit leaves at most wider_curve_excess of the held-out
  /// excess the ordinary one leaves, the whole diagnosis runs a second time widened, and is kept when its model
  /// predicts the held-out data better by the ambiguity margin; otherwise the ordinary diagnosis stands.
  bool widen_off_nominal = true;
  double wider_curve_excess = 0.75;
  /// That second diagnosis stops before its pairs, the ordinary one standing, when its best single effect
  /// does not leave less of the held-out excess than the ordinary's best by the ambiguity margin (false: its
  /// pairs always run, as before 2026-11-30; the answers were the same on the 240 evaluation cases).
  bool stop_wide_without_better_single = true;
  double false_alarm_rate = 0.01;     ///< of the `none` test (level per window, Bonferroni, plus whiteness)
  bool forward_pairs = false;         ///< also rank second effects by their coarse grid in the leader's residual
  double mixture_gain = 0.5;          ///< a second effect must remove at least this share of the excess the first leaves
  bool pair_refit_inside = true;      ///< a second effect is named only when the pair's nominal refit stays inside
                                      ///< its tolerance (else it is reported as withheld)
  double ambiguity_margin = 0.1;      ///< candidates whose held-out excess differs by less than this share of the
                                      ///< nuisance-only excess explain the data equally well
  double validation_fraction = 0.3;   ///< share of every block held out (its end; of each third of a short
                                      ///< recording, see held_out_mask)
  double validation_block_s = 10.0;   ///< held-out data: the last 30% of every 10 s block, a block at least
                                      ///< kMinValidationBlockSamples long (a recording shorter than two blocks:
                                      ///< 30% of each third, see held_out_mask)
  double window_s = 1.0;              ///< localisation window
  double significance_block_s = 0.5;  ///< held-out comparisons average squared errors over blocks this long (the pair test: at most, see pair_block_s)
  double window_flag_ratio = 1.3;     ///< window RMS / noise above which a window is a mismatch
  double none_ratio = 1.15;           ///< overall RMS / noise at or below which the model explains the data
  double penalty_per_parameter = 0.02;  ///< relative validation-MSE penalty per parameter of the effect's specs, less
                                        ///< unpenalised_parameters (form flags, a drift's unused wander); a scale reference
                                        ///< and a drift's held offset still count (docs/diagnose-evaluation-log.md)
  double tie_fit_gain = 0.25;         ///< of two candidates the held-out data cannot separate (ambiguity_margin), the
                                      ///< runner-up leads when its fit-segment excess MSE is this share lower
  double ambiguity_fit_gain = 0.5;    ///< a candidate that explains the held-out data as well as the verdict is
                                      ///< not called ambiguous when the verdict's fit-segment excess MSE is this
                                      ///< share lower than its own (stricter than tie_fit_gain: an order between
                                      ///< two near-equal answers needs less evidence than dropping one of them)
  double explained_excess = 0.5;      ///< the chosen effect must leave at most this share of the excess held-out MSE
  int candidates_to_fit = 10;          ///< the leading candidates (by evidence) that are fitted fully
  /// Runs task(i) for every i below count and returns when all are done; the tasks are independent (each
  /// has its own simulation state), so they may run at once. Empty: one after another. The diagnosis
  /// starts no threads itself; `pvcgel diagnose` passes a pool. Results do not depend on it.
  std::function<void(std::size_t count, const std::function<void(std::size_t)>& task)> run_tasks;
  /// Told after each task of a stage ends: the stage ("candidate fits", ...), the tasks done and the
  /// stage's task count. Called from the tasks, so from run_tasks' threads at once. Empty: not told.
  std::function<void(std::string_view stage, std::size_t done, std::size_t total)> progress;
};

/// A stretch of a recording where the residual exceeds the noise.
struct MismatchWindow {
  int recording = 0;
  double t_start_s = 0.0, t_end_s = 0.0;
  std::string regime;  ///< voltage level, amplitude, direction, frequency
  double rms_um = 0.0;
};

/// Errors of one model over the fit and validation segments.
struct ModelErrors {
  double rmse_um = 0.0;             ///< all samples
  double rmse_fit_um = 0.0;         ///< fit segments
  double rmse_validation_um = 0.0;  ///< held-out segments
};

/// One fitted candidate.
struct CandidateResult {
  /// As fitted: on the nominal's displacement before the refit's gain (its parameters in um are in those
  /// units); in_recorded_units() gives them as the recordings measure them.
  Effect effect;
  std::vector<ParameterSpec> specs;
  double evidence_r2 = 0.0;  ///< share of the fit-segment residual variance its best coarse-grid member explains
  bool fitted = false;       ///< refined by least squares (the leading candidates only)
  /// Why the recordings cannot show this fit as its physics (unobserved_by), so it is ranked after every
  /// candidate they can show and never named; empty when they can.
  std::string unobserved;
  /// Fitted, and the recordings can show it: it may lead, be named, alone or in a pair, or be ambiguous.
  [[nodiscard]] bool nameable() const noexcept { return fitted && unobserved.empty(); }
  ModelErrors errors;
  double score = 0.0;        ///< penalised validation MSE (lower is better)
  double time_scale = 1.0, poly_shape = 1.0, gain = 1.0;  ///< the nominal refit fitted jointly with it
  double poly_next = 0.0;  ///< f's added term, as its slope share (see DiagnosisOptions::poly_next_tolerance)
  /// The effect on the displacement the recordings measure: the refit's gain folded in (the form the
  /// report and the augmented model, whose f carries that gain, give it in).
  [[nodiscard]] Effect in_recorded_units() const { return with_displacement_scaled(effect, gain); }
  /// A loop's start per recording (AugmentedPlant::set_loop_memory: 0 virgin, +1 rising, -1 falling branch,
  /// between: partway, by a step of that share of the widest play),
  /// a nuisance chosen with the loop's fit; empty for the other candidates.
  std::vector<double> loop_memory;
  /// A slew limit's drive start per recording (Problem::set_drive_at_rest: 1 where the actuator rests, 0 at
  /// the analysis's start), a nuisance chosen with the slew limit's fit; empty for the other candidates.
  std::vector<char> drive_at_rest;
  int simulations = 0;
  std::string explanation;
};

/// Timing, initial state and offset: nuisance parameters estimated from the data, never effects.
struct Alignment {
  double io_delay_samples = 0.0;        ///< estimated from the data (sub-sample when the fit curvature supports it)
  std::optional<int> declared;          ///< what the model file says (empty: silent)
  double used_samples = 0.0;            ///< the delay the analysis runs with
  std::vector<double> offset_um;        ///< sensor offset per recording (measured minus model at rest)
  std::vector<double> initial_V;        ///< the rest voltage each recording's simulation starts from
  std::string note;                     ///< a plain sentence when estimate and file disagree
  /// The delay search's best fit at a whole delay longer than the declared one, each with its own
  /// nuisance refit, when the estimate is longer than declared (empty otherwise, and in a pass at another
  /// delay than the declared one).
  struct LongerDelay {
    int samples = 0;
    double sse_um2 = 0.0;  ///< squared error over the fitted samples
  };
  std::optional<LongerDelay> longer_delay;
  /// How much more squared error the nuisance-only refit at the declared delay leaves than longer_delay's,
  /// in noise variances (0 without one): the evidence for a delay beyond the file's that G's refitted time
  /// scale may otherwise absorb.
  double declared_delay_excess_noise_variances = 0.0;
};

/// The bounded refit of the nominal model: overall gain, G's time scale and f's shape within
/// tolerance. With a verdict naming effects, the parameters are those fitted jointly with them
/// (what the augmented model runs); `errors` are always those of the nuisance-only refit.
struct NominalRefit {
  double gain = 1.0, time_scale = 1.0, poly_shape = 1.0;
  double poly_next_slope = 0.0;  ///< f's added odd term: its slope at the largest |u| over f's mean slope there
  double poly_next = 0.0;        ///< its coefficient (of x^(2n+1), n = the nominal's number of terms)
  ModelErrors errors;
  double fit_sse_um2 = 0.0;      ///< the nuisance-only refit's squared error over the fitted samples
  /// The parameters above that stop at their tolerance (refit_at_bounds), by JSON key: those fitted with
  /// the named effects when there are any, else the nuisance-only refit's.
  std::vector<std::string> at_bounds;
  /// Whether the parameter `name` (its JSON key) is among at_bounds.
  [[nodiscard]] bool at_bound(std::string_view name) const {
    return std::find(at_bounds.begin(), at_bounds.end(), name) != at_bounds.end();
  }
  /// The parameters of the nuisance-only refit that stopped at the ordinary tolerances when the diagnosis
  /// widened them (DiagnosisOptions::widen_off_nominal); empty when it did not (or when the shape alone
  /// stopped and the widened refit did not make the data `none`).
  std::vector<std::string> widened_from;
  [[nodiscard]] bool widened() const noexcept { return !widened_from.empty(); }
};

/// Whether a refit parameter (its JSON key, as in NominalRefit::at_bounds) is one of f's terms: its shape
/// or its added term, which a static curve's effect (a dead zone, a saturation) bends as well.
inline bool is_f_term(std::string_view name) noexcept { return name == "poly_shape" || name == "poly_next_slope"; }

/// The statistical `none` test on the residual of the nuisance-only refit.
struct NoneTest {
  double false_alarm_rate = 0.01;
  int windows = 0;                 ///< windows the level test looked at (Bonferroni-corrected over these)
  double worst_window_ratio = 0.0; ///< largest window mean-square residual / noise variance
  double window_threshold = 0.0;   ///< its threshold at the corrected level
  double whiteness_q = 0.0, whiteness_threshold = 0.0;  ///< largest Ljung-Box statistic over recordings and its threshold
  bool level_ok = true, white = true;
  /// Passed, but a longer I/O delay than the file's fitted clearly better (Alignment::declared_delay_excess_noise_variances):
  /// the candidates judged it before `none` was decided.
  bool longer_delay_pending = false;
};

/// A one-sided test that model b predicts the held-out data better than model a.
struct HeldOutTest {
  double mean_um2 = 0.0;   ///< mean held-out squared-error reduction (a's MSE minus b's)
  double t = 0.0, threshold = 0.0;  ///< the t statistic and its threshold at half the level
  double signed_rank_p = 1.0;       ///< one-sided p-value of the Wilcoxon signed-rank test on the blocks
  int blocks = 0;           ///< blocks tested
  bool significant = false;
};

/// One pair fitted jointly (SecondEffectTest::tried): how well it fits, and the score the best pair is chosen by.
struct PairTried {
  /// The leader, then the second effect fitted beside it; in the exchange step's pairs a runner-up in the
  /// leader's place, then the best pair's second effect.
  std::vector<std::string> effects;
  double rmse_fit_um = 0.0;
  double rmse_validation_um = 0.0;
  double score = 0.0;  ///< the judging segment's MSE with the per-parameter penalty (Excess::score)
};

/// The test of the best pair of effects fitted (DiagnosisResult::second_effect_test): why a second effect was
/// named or not, so that a mixture left unnamed can be followed up.
struct SecondEffectTest {
  std::vector<std::string> effects;  ///< the pair fitted, the larger contribution first (empty: no pair fitted)
  /// Every pair fitted, the lowest score (the best pair) first: whether a second effect was fitted at all
  /// beside the leader, and how close the others came.
  std::vector<PairTried> tried;
  double rmse_validation_um = 0.0;   ///< the pair's held-out RMSE
  /// Per member: the pair against the other member alone on held-out blocks (its contribution, mean_um2).
  std::array<HeldOutTest, 2> member{};
  bool explained = false;  ///< the pair leaves at most DiagnosisOptions::explained_excess of the excess
  bool material = false;   ///< each member removes enough of what the other leaves (DiagnosisOptions::mixture_gain)
  bool named = false;      ///< both named (false also when the second was withheld: DiagnosisResult::withheld_second)
  /// The best single effect's held-out RMSE over the estimated noise (0: none fitted). Within
  /// kSingleAtTheNoise the held-out data hold nothing a second effect could remove, so none can be significant.
  double single_over_noise = 0.0;
  /// The best single effect leaves the held-out data at the noise (single_over_noise within kSingleAtTheNoise).
  [[nodiscard]] bool single_at_the_noise() const noexcept;
};

/// A best single effect whose held-out RMSE is within this factor of the noise leaves no room for a second.
inline constexpr double kSingleAtTheNoise = 1.05;

inline bool SecondEffectTest::single_at_the_noise() const noexcept {
  return single_over_noise > 0.0 && single_over_noise <= kSingleAtTheNoise;
}

/// The outcome.
struct DiagnosisResult {
  std::string verdict;  ///< an effect name, "none" or "unexplained"
  EffectKind chosen = EffectKind::none;  ///< effect of the augmented model (none for "none"/"unexplained")
  Effect effect;        ///< the chosen (dominant) effect with its fitted parameters
  std::vector<Effect> mixture;  ///< the effects of the augmented model, dominant first (empty for none/unexplained)
  std::vector<double> contribution;  ///< per mixture element: held-out MSE it removes (um^2)
  std::vector<std::string> ambiguous_with;  ///< effects that explain the held-out data as well as the verdict
  std::string separating_experiment;        ///< what would tell them apart (when ambiguous_with is not empty)
  /// Where the candidates were ranked and judged: "held_out", or "fitting_segment" when the held-out data
  /// carry no excess (the mismatch lies in the fitting segment only); empty when none were fitted (`none`).
  std::string candidates_judged_on;
  /// A second effect significant on held-out data beside the verdict but not named, because the pair's
  /// nominal refit stops at its tolerance on `withheld_at_bounds` (it may stand in for the nominal's error).
  std::string withheld_second;
  std::vector<std::string> withheld_at_bounds;
  SecondEffectTest second_effect_test;
  Alignment alignment;
  NominalRefit nominal_refit;
  NoneTest none_test;
  std::string explanation;
  double noise_sigma_um = 0.0;
  ModelErrors baseline, fitted;  ///< baseline: the nominal model as declared (estimated delay if silent); fitted: the verdict's
  ModelErrors aligned;           ///< the nominal model with the sensor offset and start state fitted
  std::vector<CandidateResult> candidates;  ///< ranked best first (fitted ones by score, then the rest by evidence)
  std::vector<MismatchWindow> mismatch;
  std::vector<std::vector<double>> y_baseline_um, y_fitted_um;  ///< per recording
  std::vector<std::vector<char>> held_out;  ///< per recording and sample: 1 when held out (validation)
  std::vector<std::string> held_out_rule;   ///< per recording: how its held-out samples were chosen (held_out_rule)
  std::vector<double> window_centre_s, window_rms_um;  ///< all windows of all recordings (for plots)
  std::vector<int> window_recording;
  int simulations = 0;
};

/// Which samples of an n-sample recording are held out (1) rather than fitted (0): the last 30% of every
/// block; a recording shorter than two blocks 30% of each third (the first third's end, the second's middle,
/// the last's start), so neither of its ends is held out; one under 3 kMinValidationBlockSamples, its last 30%.
std::vector<char> held_out_mask(size_t n, double sample_time_s, const DiagnosisOptions& options = {});
/// held_out_mask's rule for that recording in words, in seconds when a block is at least 1 s: "the last 3 s
/// of every 10 s block", "the last 30 of every 100 samples", "30% of each third, neither end (...)".
std::string held_out_rule(size_t n, double sample_time_s, const DiagnosisOptions& options = {});

/// Sensor-noise standard deviation from the data: robust (median) scale of
/// the second differences of y, which the slow actuator dynamics leave to the noise.
double estimate_noise_sigma(const std::vector<double>& y_um);

/// A readable label of the regime of u over [begin, end).
std::string describe_regime(const Series& s, size_t begin, size_t end);

/// Checks a series: uniform, monotone time, finite values, long enough for G's
/// slowest time constant. @throws std::invalid_argument naming the sample and reason.
void check_series(const Series& s, const HammersteinModel& model);

/// The parameters of a nominal refit that stop at their tolerance ("gain", "time_scale", "poly_shape",
/// "poly_next_slope"; `with_loop`: G's time scale may go down to hysteresis_time_scale_min). A refit fitted
/// with the named effects that stops there says the nominal model is further off than the refit may move
/// it, and the effects may stand in for part of that model error; a nuisance-only refit may also stop
/// there because it absorbs what an effect would explain.
std::vector<std::string> refit_at_bounds(const NominalRefit& refit, const DiagnosisOptions& options, bool with_loop);

/// The tolerances of the refit when the nominal's static curve is far off: gain within [0.25, 4], f's shape
/// within [0.25, 4], f's next term's slope share within +-3, f kept increasing only to 1.05 times the largest
/// recorded |u| (or the file's controller range): the n = 2 polynomial of one identification refits to the
/// n = 3 polynomial of another, which turns over just above the recorded voltages.
DiagnosisOptions widened_tolerances(DiagnosisOptions options);

/// Whether the diagnosis run at widened_tolerances, `wide`, predicts the held-out data clearly better than the
/// ordinary one, `ordinary`: its model (the named effects, or the nuisance-only refit when none is named) leaves
/// less of the ordinary nuisance-only refit's excess MSE by DiagnosisOptions::ambiguity_margin of it. Asked
/// when f's shape alone stopped at its bound (DiagnosisOptions::wider_curve_excess).
bool widened_predicts_better(const DiagnosisResult& ordinary, const DiagnosisResult& wide, const DiagnosisOptions& options);

/// f's shape bounds of the refit: 1 -+ tol below a tolerance of 1, [1 / (1 + tol), 1 + tol] from 1 on.
std::pair<double, double> poly_shape_bounds(const DiagnosisOptions& options);

/// The overall gain's bounds of the refit: [1 / (1 + tol), 1 + tol].
std::pair<double, double> gain_bounds(const DiagnosisOptions& options);

/// G's time-scale bounds of the refit: [1 / (1 + tol), 1 + tol]; `with_loop`, the lower one down to
/// DiagnosisOptions::hysteresis_time_scale_min.
std::pair<double, double> time_scale_bounds(const DiagnosisOptions& options, bool with_loop = false);

/// Simulates `model` (with `effect`) from each recording's u, output error,
/// from rest at the voltage whose steady state matches the mean of the first
/// 10 measured samples (the recording's initial state; for an open-loop
/// recording that starts at rest this is u[0]). No nuisance fit: the raw model.
std::vector<std::vector<double>> simulate(const HammersteinModel& model, const Effect& effect,
                                          const std::vector<Series>& data, int io_delay_samples);

/// The model with G's time constants multiplied by `time_scale`, f's coefficients above the
/// linear one by `poly_shape`, and f's next odd term with coefficient `poly_next` appended
/// (the bounded nominal refit).
HammersteinModel refit_model(const HammersteinModel& model, double time_scale, double poly_shape, double poly_next = 0.0);

/// G with every time constant multiplied by `factor` (G(factor s)): same DC gain.
TransferFunction time_scaled(const TransferFunction& G, double factor);


/// One-sided p-value P(W+ >= observed) of the Wilcoxon signed-rank statistic of `x` (zeros dropped,
/// average ranks on ties) under symmetry about 0: exact up to 300 values, the normal approximation above.
double signed_rank_p(const std::vector<double>& x);

/// Compares two predictions on the held-out samples: the squared-error differences averaged in blocks
/// of `block_s` seconds (a model error is correlated in time), b better than a when either of two one-sided
/// tests passes at half of `level` (Bonferroni): their mean against its standard error (Student t, blocks - 1
/// degrees of freedom), or their signed ranks (Wilcoxon, signed_rank_p). Blocks where the two predictions
/// differ by less than `indistinct_um2` (mean square) carry no evidence and are left out of the test (not of
/// `mean_um2`, which is over every block). Fewer than 3 blocks tested: not significant.
HeldOutTest held_out_improvement(const std::vector<Series>& data, const std::vector<std::vector<double>>& y_a,
                                 const std::vector<std::vector<double>>& y_b, const std::vector<std::vector<char>>& held_out,
                                 double block_s, double level, double indistinct_um2 = 0.0);

/// The share of the nuisance-only refit's excess (above-noise) MSE that a model with errors `e` still leaves,
/// on the verdict's yardstick: the held-out data when the mismatch reaches them, else the fit segment (a
/// verdict needs at most DiagnosisOptions::explained_excess). NaN when the refit leaves no excess.
double excess_share_left(const DiagnosisResult& res, const ModelErrors& e);

/// What kept the best pair's second effect out of the mixture, one phrase each ("saturation not significant",
/// "the pair leaves over half the excess", "not material", or "withheld" when every test passed), and "the best
/// single effect alone at the noise" beside them (SecondEffectTest::single_over_noise): empty when
/// both were named or no pair was fitted. `members` names the two members in the phrases (default: their
/// effects; the suite names them by the labels, "the dominant" and "the other").
std::vector<std::string> second_effect_shortfalls(const SecondEffectTest& test,
                                                  std::array<std::string, 2> members = {});

/// The name of a loop's start (CandidateResult::loop_memory): "rising", "falling", "virgin", or "partway
/// rising" / "partway falling" (a share of the widest play's width, AugmentedPlant::set_loop_memory).
std::string_view loop_start_name(double branch) noexcept;

/// Full diagnosis. @throws std::invalid_argument on bad data (see check_series),
/// ConfigError on a model that cannot be simulated (unstable G, non-monotone f
/// over the recorded voltage range).
DiagnosisResult diagnose(const HammersteinModel& model, const std::vector<Series>& data,
                         const DiagnosisOptions& options = {});

}  // namespace pvcgel::control::diagnosis
