#pragma once
/// @file
/// Effects beyond the Hammerstein model: small, physically meaningful
/// augmentations that `pvcgel diagnose` fits, and a plant that runs the model
/// with one of them (the form that is fitted to recordings and that the
/// simulated rig runs after a diagnosis).

#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cstdint>
#include <cmath>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "control/enum_table.hpp"
#include "control/hammerstein_model.hpp"

namespace pvcgel::control {

struct StateSpace;

/// What the nominal model may be missing.
enum class EffectKind : std::uint8_t {
  none,
  hysteresis,
  creep,
  dead_zone,
  saturation,
  delay,
  asymmetric_dynamics,
  slew_limit,
  resonance,
  drift,
  bias_dependent_dynamics,
};

/// The ten candidate effects, in the order of the issue.
inline constexpr std::array<EffectKind, 10> kCandidateEffects{
    EffectKind::hysteresis, EffectKind::creep,      EffectKind::dead_zone,           EffectKind::saturation,
    EffectKind::delay,      EffectKind::asymmetric_dynamics, EffectKind::slew_limit, EffectKind::resonance,
    EffectKind::drift,      EffectKind::bias_dependent_dynamics};

/// Name used in reports and files ("hysteresis", ..., "none").
inline constexpr auto kEffectKindNames = enum_table<EffectKind::none, EffectKind::bias_dependent_dynamics>(
    {"none", "hysteresis", "creep", "dead_zone", "saturation", "delay", "asymmetric_dynamics", "slew_limit", "resonance",
     "drift", "bias_dependent_dynamics"});
constexpr const auto& names_of(EffectKind) noexcept { return kEffectKindNames; }
constexpr std::string_view to_string(EffectKind kind) noexcept { return kEffectKindNames.to_string(kind); }
/// Inverse of to_string.
constexpr std::optional<EffectKind> parse_effect_kind(std::string_view name) noexcept {
  return kEffectKindNames.parse(name);
}

/// One physical parameter of an effect.
struct ParameterSpec {
  std::string name;         ///< key in files and JSON, with its unit (e.g. "time_constant_s")
  double lower = 0.0;       ///< bounds the fit respects
  double upper = 0.0;
  bool log_scale = false;   ///< fitted in log space (positive scale parameters)
  std::vector<double> starts;  ///< coarse grid of starting values for the fit
  /// Value when a file omits the key (NaN: the key is required). Parameters
  /// added after the format was first written have one, so old files still load.
  double default_value = std::numeric_limits<double>::quiet_NaN();
  /// Set from the recording's scale (lower == upper), not fitted: a reference that makes the other
  /// parameters dimensionless for any actuator.
  bool fixed = false;
  /// The unit's power of the displacement unit: 1 for um, um/s, um/sqrt(s), 0 for volts, seconds and
  /// shares. A plant whose displacement is k times as large has this parameter k^displacement_power times
  /// as large (with_displacement_scaled).
  int displacement_power = 0;
};

/// `spec` in micrometres (displacement_power 1).
inline ParameterSpec in_micrometres(ParameterSpec spec) {
  spec.displacement_power = 1;
  return spec;
}

/// The longest extra delay the diagnosis fits, in samples of the fastest recording.
inline constexpr double kFittedDelaySamples = 236.0;
/// The longest extra delay a file may give, in samples of its loop period: the plant sizes its delay
/// line to the delay at construction, so a delay fitted on a 100 Hz recording runs in a 1 kHz sim.
inline constexpr double kMaxDelaySamples = 65536.0;

/// The |value| nearest zero of the range lo..hi (0 when the range crosses zero).
[[nodiscard]] constexpr double abs_nearest_zero(double lo, double hi) noexcept {
  return lo >= 0.0 ? lo : (hi <= 0.0 ? -hi : 0.0);
}

/// The size of what was recorded: parameter bounds and starting points scale
/// with it, so the same candidates work from millivolt amplifier inputs to a
/// kilovolt, nanometre to millimetre strokes and 100 Hz to 10 kHz sampling.
struct DataScale {
  double sample_time_s = 1e-3;      ///< the longest sample time of the recordings
  double sample_time_min_s = 0.0;   ///< the shortest (0: the same); the delay line's length counts these
  double duration_s = 30.0;   ///< the longest recording
  /// The earliest end of a recording's fit segment (s after its start; the rest is held out): a drift
  /// that starts after it acts on held-out data alone, where nothing fitted it.
  double fit_end_s = std::numeric_limits<double>::infinity();
  double u_min_V = 0.0, u_max_V = 1000.0;  ///< recorded command range
  double y_min_um = 0.0, y_max_um = 200.0;  ///< the stroke, recorded or by the nominal simulation
  /// The largest |displacement|.
  [[nodiscard]] double y_abs_um() const noexcept { return std::max({std::abs(y_min_um), std::abs(y_max_um), 1e-12}); }
  /// The stroke has both signs, each a tenth of the largest |displacement| or more: it has a stop on each
  /// side, which need not lie at the same height.
  [[nodiscard]] bool bipolar_stroke() const noexcept { return std::min(-y_min_um, y_max_um) >= 0.1 * y_abs_um(); }
  /// The middle of the nominal's own displacement when known (model_y_*), else of the recorded stroke.
  [[nodiscard]] double y_middle_um() const noexcept {
    const DataScale m = on_model_displacement();
    return 0.5 * (m.y_min_um + m.y_max_um);
  }
  /// The |displacement| nearest zero of a one-signed stroke (0 when it crosses zero): a sensor zeroed
  /// elsewhere records a stroke from 74 to 125 um, whose stop lies within that range, not within 0..125.
  [[nodiscard]] double y_abs_nearest_um() const noexcept {
    return abs_nearest_zero(y_min_um, y_max_um);
  }
  double delay_samples_max = kFittedDelaySamples;  ///< the delay effect's bound, in sample_time_min_s
  /// The nominal's own displacement under the nuisance refit, before its gain ((y - offset) / gain;
  /// diagnosis::cover_model_displacement), where a saturation's knee acts; NaN until known.
  double model_y_min_um = std::numeric_limits<double>::quiet_NaN(), model_y_max_um = std::numeric_limits<double>::quiet_NaN();
  /// This scale with the stroke widened over the nominal's own displacement (model_y_*), when known.
  [[nodiscard]] DataScale on_model_displacement() const noexcept {
    DataScale m = *this;
    if (model_y_min_um <= model_y_max_um)
      m.y_min_um = std::min(y_min_um, model_y_min_um), m.y_max_um = std::max(y_max_um, model_y_max_um);
    return m;
  }
  /// The |command| nearest zero (0 when the commands cross zero): a closed loop about a bias records no
  /// voltage below hundreds of volts.
  [[nodiscard]] double u_abs_nearest_V() const noexcept {
    return abs_nearest_zero(u_min_V, u_max_V);
  }
  [[nodiscard]] double u_span_V() const noexcept { return std::max(u_max_V - u_min_V, 1e-9); }
  [[nodiscard]] double u_abs_V() const noexcept { return std::max({std::abs(u_min_V), std::abs(u_max_V), 1e-9}); }
  /// The largest and smallest scales: a file's parameters (nothing recorded to
  /// scale by) are checked against the union of their bounds, physical limits only.
  static DataScale unbounded(double sample_time_s) noexcept {
    return {.sample_time_s = sample_time_s, .duration_s = 1e300, .u_min_V = -1e12, .u_max_V = 1e12,
            .y_min_um = -1e12, .y_max_um = 1e12, .delay_samples_max = kMaxDelaySamples};
  }
  static DataScale tiny(double sample_time_s) noexcept {
    return {.sample_time_s = sample_time_s, .duration_s = 0.0, .u_min_V = -1e-12, .u_max_V = 1e-12,
            .y_min_um = -1e-12, .y_max_um = 1e-12};
  }
};

/// Maximum number of parameters of one effect.
inline constexpr int kMaxEffectParams = 6;

/// Maximum number of effects one plant runs at once (a mixture of two).
inline constexpr int kMaxEffects = 2;

/// An effect with its parameters (meaning per kind: see parameter_specs()).
struct Effect {
  EffectKind kind = EffectKind::none;
  std::array<double, kMaxEffectParams> p{};
};

/// Number of play operators of the hysteresis effect.
inline constexpr int kHysteresisPlays = 8;
/// Play thresholds at threshold_spread 0: r_i = threshold_scale_V * kPlayQuantiles[i]
/// (ascending), the quantiles of an exponential distribution (mean 1): the lag
/// after a reversal grows linearly, then saturates exponentially.
inline constexpr std::array<double, kHysteresisPlays> kPlayQuantiles{0.0645, 0.2076, 0.3677, 0.5596,
                                                                     0.7985, 1.0986, 1.5041, 2.0794};

/// Largest hysteresis alpha the controller compensates (EffectCompensator): the
/// inverse's slope right after a reversal is 1 / (1 - alpha); above 10 it turns
/// sensor noise into voltage steps. `pvcgel diagnose` fits alpha below it.
inline constexpr double kMaxCompensatedHysteresisAlpha = 0.9;

/// The hysteresis effect's play thresholds (ascending, so the operator stays
/// invertible): r_i = R q_i^(1 + spread), q_i = kPlayQuantiles[i]. The spread
/// shapes the loop: 0 is the exponential distribution (the form before the
/// parameter existed); positive spreads the thresholds over more decades
/// (sub-volt and wide loops at once: a loop that rounds off slowly); negative
/// gathers them around R (-0.85: within -35%..+10%, a loop with sharp corners,
/// close to one backlash of width 2R).
inline std::array<double, kHysteresisPlays> play_thresholds(double R_V, double spread) noexcept {
  std::array<double, kHysteresisPlays> r{};
  for (size_t i = 0; i < r.size(); ++i) r[i] = R_V * std::pow(kPlayQuantiles[i], 1.0 + spread);
  return r;
}

/// The dead zone effect: no response up to d, linear catch-up to u over the
/// next w volts, then u (odd, for bipolar drive).
inline double dead_zone(double u_V, double d_V, double w_V) noexcept {
  const double a = std::abs(u_V);
  return std::copysign(a <= d_V ? 0.0 : (a <= d_V + w_V ? (a - d_V) * (d_V + w_V) / w_V : a), u_V);
}

/// The saturation effect's soft knee, its parameters q = (knee, softness, on_drive, centre): y farther than
/// `knee` from `centre` softens as knee + e / sqrt(1 + (e / softness)^2) (odd about the centre: both stops of a
/// bipolar stroke; a centre off zero puts them at different heights), approaching knee + softness.
inline double soft_saturation(double y, const std::array<double, kMaxEffectParams>& q) noexcept {
  const double from_centre = y - q[3], excess = std::abs(from_centre) - q[0];
  return excess > 0.0 ? q[3] + std::copysign(q[0] + excess / std::sqrt(1.0 + (excess / q[1]) * (excess / q[1])), from_centre)
                      : y;
}

/// The saturation effect on the drive (on_drive): G's input for f's output w, the soft knee acting on the
/// static displacement G(0) w it would give (`q` the saturation's parameters).
inline double saturated_drive(double w, double dc_gain, const std::array<double, kMaxEffectParams>& q) noexcept {
  return soft_saturation(dc_gain * w, q) / dc_gain;
}
/// d soft_saturation / dy: 1 below the knee, (1 + (excess / softness)^2)^(-3/2) beyond it.
inline double soft_saturation_slope(double y, const std::array<double, kMaxEffectParams>& q) noexcept {
  const double excess = std::abs(y - q[3]) - q[0], r2 = (excess / q[1]) * (excess / q[1]);
  return excess > 0.0 ? 1.0 / ((1.0 + r2) * std::sqrt(1.0 + r2)) : 1.0;
}

/// The slew-limit effect over one sample: the drive moves from its state toward
/// the command (difference e) at most `cap` volts per sample; returns what the
/// gel sees over the sample relative to the state. An analog amplifier ramps
/// inside the sample (its mean); a digital limiter holds the limited step.
inline double slew_mean_offset(double e_V, double cap_V, bool digital) noexcept {
  if (digital) return std::clamp(e_V, -cap_V, cap_V);
  return std::abs(e_V) <= cap_V ? e_V - 0.5 * e_V * std::abs(e_V) / cap_V : std::copysign(0.5 * cap_V, e_V);
}
/// ... and the state's move over the sample.
inline double slew_state_step(double e_V, double cap_V) noexcept { return std::clamp(e_V, -cap_V, cap_V); }

/// The drift effect's term t_s after the run's start (the recording's, or the controller's reset): the
/// offset, then from the onset a ramp at rate_um_per_s that settles exponentially over settling_time_s
/// (thermal settling: it ends rate * settling_time_s away); settling_time_s 0, the default of files written
/// before the key existed, is a ramp that never settles.
inline double drift_um(const std::array<double, kMaxEffectParams>& q, double t_s) noexcept {
  const double t = std::max(t_s - q[2], 0.0);
  return q[0] + q[1] * (q[3] > 0.0 ? -q[3] * std::expm1(-t / q[3]) : t);
}

/// The drift effect's parameter that makes it wander (wander_um_per_sqrt_s, 0: a drift that does not).
inline constexpr size_t kDriftWander = 4;

/// Kelvin-Voigt creep branches (fraction of G(0), time constant in s) of a creep
/// effect's parameters: one at tau, or three (fraction / 3 each) spread
/// log-uniformly over `spread_decades` around tau (log-type creep).
std::vector<std::pair<double, double>> creep_branches(const std::array<double, kMaxEffectParams>& p);

/// G has a real pole slower than all its others (and at least two): asymmetric or bias-dependent dynamics may
/// move it alone (slow_pole_only).
bool slowest_pole_is_real(const TransferFunction& G);

/// "name = value, ..." of an effect's parameters (`specs` its parameter_specs), four digits each.
std::string parameters_text(const Effect& e, const std::vector<ParameterSpec>& specs);

/// The same effect on a plant whose displacement is `factor` times as large (a gain folded into f): each
/// parameter scales by factor^displacement_power (its spec's: a saturation's knee, softness and centre, a
/// drift, the bias-dependent dynamics' reference and centre by `factor`), the others (volts, seconds,
/// shares) stay.
Effect with_displacement_scaled(const Effect& e, double factor);

/// Where `kind` keeps the parameter that chooses between its two forms (0 or 1: saturation's on_drive,
/// slew_limit's digital, slow_pole_only), if it has one.
std::optional<size_t> form_flag_index(EffectKind kind) noexcept;

/// Where `kind` keeps its slow_pole_only choice (asymmetric and bias-dependent dynamics), if it has one.
std::optional<size_t> slow_pole_only_index(EffectKind kind) noexcept;

/// Whether `e` moves G's slowest pole alone (slow_pole_only = 1).
bool moves_slow_pole_only(const Effect& e) noexcept;

/// G with the linear effects of `effects` folded in (creep branches in parallel,
/// a structural mode in series), the linear block AugmentedPlant runs; G itself
/// when neither is present.
TransferFunction linear_block(const TransferFunction& G, std::span<const Effect> effects);

/// Parameters of `kind` with bounds and fit starts, scaled to the data.
std::vector<ParameterSpec> parameter_specs(EffectKind kind, const DataScale& scale);

/// One sentence on what the effect is, in physical terms.
std::string_view physical_meaning(EffectKind kind) noexcept;

/// Checks parameters against their physical bounds. @throws ConfigError naming `key`.
void validate(const Effect& effect, double sample_time_s, const std::string& key);

/// Checks that `effects` can run together in one plant (at most kMaxEffects,
/// no kind twice).
/// @throws ConfigError naming `key`.
void validate_mixture(std::span<const Effect> effects, const std::string& key);

/// The Hammerstein model with up to kMaxEffects added effects, stepped with the
/// daemon's convention: output() is the displacement at the start of cycle k,
/// apply(u) holds u over the cycle and advances one sample. The nominal model
/// (EffectKind::none) is exactly SimulatedRig without sensor effects.
/// Candidate forms (the generator in generator.hpp uses different ones):
///  - hysteresis: Prandtl-Ishlinskii play operators on the voltage,
///    x = u - alpha mean_i(u - play_{r_i}(u)), r_i = play_thresholds(R, spread)
///    (alpha the hysteretic share, R the threshold scale, spread the loop's shape; alpha > 0 is the
///    usual counter-clockwise loop, the output lagging after a reversal, alpha < 0 a clockwise one);
///  - creep: Kelvin-Voigt branches fraction G(0) / (tau s + 1) in parallel with G: one
///    branch, or (spread_decades > 0) three with fraction / 3 each at tau 10^(-spread/2, 0, +spread/2),
///    a log-type creep; a negative fraction with the refitted gain is creep that keeps the DC gain;
///  - dead_zone: no response below threshold d, linear catch-up to u at 2 d;
///  - saturation: y farther than a knee from a centre (0 by default) softens as knee + e / sqrt(1 + (e / Y)^2)
///    (both signs: bipolar strokes, with stops at different heights when the centre is off zero;
///    soft_saturation); on_drive 0 on the displacement (a stroke stop), 1 on G's input, the drive, in units of
///    the static displacement G(0) f it would give (an amplifier or an actuator force that saturates: the
///    displacement then approaches the limit with G's dynamics);
///  - delay: extra transport delay, fractional too: the held command switches d samples into a sample
///    period, so G's state takes the old held value's drive over d Ts and the new one's over (1 - d) Ts
///    (exact for a held command, ZOH with a delayed switch; D takes the new value);
///  - asymmetric_dynamics: G runs (1 + kappa) times slower while relaxing; slow_pole_only 1: only G's slowest
///    real pole does, as for bias_dependent_dynamics (a direction-dependent viscoelastic relaxation, the fast
///    dynamics alike both ways), 0 (the default): all of G's time constants;
///  - slew_limit: the amplifier voltage changes at most S V/s;
///  - resonance: a structural mode M(s) = w_n^2 / (s^2 + 2 zeta w_n s + w_n^2), in series, G (d + (1 - d) M),
///    d the direct fraction (0: a full second-order low-pass; near 1: a mode with a small participation,
///    a pole pair with a zero pair just above it), and in parallel with share rho: (1 - rho) G (d + (1 - d) M)
///    + rho G(0) M (a fast mode fed by the actuator's force, not filtered by G: modal superposition; rho 0,
///    the default, is the series form alone);
///  - drift: offset + rate max(t - onset, 0), settling exponentially over settling_time_s when it is not 0
///    (drift_um), independent of the input; wander_um_per_sqrt_s > 0 adds a random walk (RMS change
///    wander sqrt(T) over T) that no prediction can follow: this plant leaves it out, SimulatedRig draws it;
///  - bias_dependent_dynamics: G runs (1 + (beta (y_op - centre) + amplitude_beta y_swing) / y_ref) times slower,
///    y_op the displacement low-passed over the operating-point time constant, y_swing |y - y_op| low-passed over
///    the same time (the amplitude of the motion about y_op), y_ref = reference_um (diagnose sets it to the
///    largest recorded displacement; 0, the default of files written before it existed: y_ref = G(0) f(500 V))
///    and centre = centre_um, the displacement at which G's time constants are the nominal's (0, the default:
///    at rest at zero; a nominal identified about an operating point holds there, not at zero);
///    slow_pole_only 1: only G's slowest real pole moves, its mode's DC gain kept (the fast dynamics do not
///    depend on the bias), 0 (the default): all of G's time constants. Beside creep or a mode the slow pole is
///    G's own: the block then runs G, the creep branches and the mode as separate states (the same transfer
///    function), and only G's slow mode moves, the creep's and the mode's poles staying where they are.
///  Asymmetric and bias-dependent dynamics together multiply their slowdowns, each on what it moves (G's slow
///    mode or all of G): the grid holds the bias's time scales once per direction.
/// Construction allocates; reset and stepping do not.
class AugmentedPlant final {
 public:
  /// @param io_delay_samples  the I/O delay, whole or fractional samples (exact for a held command, as the delay effect)
  /// @throws ConfigError if G is unstable or improper, or parameters are out of bounds.
  AugmentedPlant(const HammersteinModel& model, double io_delay_samples, double sample_time_s,
                 std::span<const Effect> effects);
  AugmentedPlant(const HammersteinModel& model, double io_delay_samples, double sample_time_s, const Effect& effect)
      : AugmentedPlant(model, io_delay_samples, sample_time_s, std::span<const Effect>(&effect, 1)) {}

  /// At rest under constant u (time zero), the play operators on the loop branch set_loop_memory chose.
  void reset_steady_state(double u_V) noexcept;
  /// The hysteresis memory a rest state starts with: 0 virgin (the default), +1 on the rising branch
  /// (reached from below: each play r_i under the input), -1 on the falling branch; between, the state a
  /// virgin loop reaches by one step of |branch| times the widest play's width, from below (> 0) or above:
  /// the plays narrower than the step on the branch, the wider ones displaced by the step. A recording that
  /// starts after a hold at another level (a single step from it) or mid-motion does not start virgin.
  void set_loop_memory(double branch) noexcept { loop_memory_ = std::clamp(branch, -1.0, 1.0); }
  /// The hysteresis effect's widest play operator, in volts (0 without one): what set_loop_memory's share is of.
  [[nodiscard]] double widest_play_V() const noexcept { return *std::max_element(play_r_.begin(), play_r_.end()); }
  /// Displacement now (start of the current cycle).
  [[nodiscard]] double output() const noexcept { return y_; }
  /// Hold u for this cycle and advance one sample.
  void apply(double u_V) noexcept;

  /// The voltage at which this plant rests with output y (bisection over
  /// [lo, hi]; the nearer end when y is out of reach). Leaves the plant at rest there.
  double rest_voltage(double y_um, double lo_V, double hi_V) noexcept;

  /// Output-error simulation: at rest at `initial_V`, then y[k] for every u[k].
  std::vector<double> simulate(std::span<const double> u_V, double initial_V);

  /// The largest pole modulus of the discretised linear block over its time-scale grid (infinite when an entry
  /// is not finite). A stable continuous block maps inside the unit circle, so 1 or more means the
  /// discretisation itself went wrong (a badly scaled exponential did once, 7fdcb00), and the plant would run to
  /// infinity. Configuration time (allocates): the sim backend checks it before it runs an augmented model.
  [[nodiscard]] double largest_discrete_pole_modulus() const;

 private:
  static constexpr int kMaxOrder = 9;
  static constexpr size_t kKinds = kEffectKindNames.size();
  static constexpr int kPlays = kHysteresisPlays;
  using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxOrder, kMaxOrder>;
  using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxOrder, 1>;

  /// f, then a saturation on the drive (on_drive), if any: G's input.
  [[nodiscard]] double nonlinearity(double x_V) const noexcept {
    const double w = f_(std::clamp(x_V, -x_sat_, x_sat_));
    return saturate_drive_ ? saturated_drive(w, dc_gain_, p(EffectKind::saturation)) : w;
  }
  [[nodiscard]] double output_stage(double y_lin, long sample) const noexcept;
  /// Bias-dependent dynamics' time scale now (from the operating point and the swing about it).
  [[nodiscard]] double bias_time_scale() const noexcept;
  /// x <- weight (A_i x + B_i w + E_i dw) + (1 - weight) (A_{i+1} x + B_{i+1} w + E_{i+1} dw): one grid entry,
  /// or two interpolated; returns C x + D w. dw is the previous drive minus w, E its share of the sample (the
  /// fractional delay's; without one, Fractional false leaves the term out of the hot loop). For the linear
  /// block's order N, chosen once at construction (with N a constant the compiler unrolls the step; a runtime
  /// order cost the diagnosis half its simulation time).
  template <int N, bool Fractional>
  double linear_step(size_t i, double weight, double w, double dw) noexcept;
  using LinearStep = double (AugmentedPlant::*)(size_t, double, double, double) noexcept;
  /// [fractional delay][order]
  static const std::array<std::array<LinearStep, kMaxOrder + 1>, 2> kLinearSteps;
  template <bool Fractional, size_t... N>
  static constexpr std::array<LinearStep, sizeof...(N)> linear_steps(std::index_sequence<N...>);
  /// apply's body.
  void advance(double u_V) noexcept;
  /// Slew limit, dead zone and hysteresis on the delayed command (this order: amplifier, then gel).
  double input_stage(double x_V) noexcept;
  // Construction's stages (configuration time: they throw ConfigError).
  /// Validates the effects and records which run, with their parameters.
  void take_effects(std::span<const Effect> effects);
  /// [A | B], C, D and E per grid entry (the time scales of asymmetric dynamics' direction times those of
  /// bias-dependent dynamics), and the rest state's factorisation at time scale 1. Each effect scales what it
  /// moves: with *_slow only G's slow mode (slow_dA, slow_dB), else the whole block.
  void discretise_grid(const StateSpace& ss, bool direction_slow, bool bias_slow, const Eigen::MatrixXd& slow_dA,
                       const Eigen::VectorXd& slow_dB);
  /// G's and the block's DC gains, the drive-side saturation switch and bias-dependent dynamics' scales.
  void set_gains(const HammersteinModel& model);

  [[nodiscard]] bool has(EffectKind k) const noexcept { return on_[static_cast<size_t>(k)]; }
  [[nodiscard]] const std::array<double, kMaxEffectParams>& p(EffectKind k) const noexcept {
    return p_[static_cast<size_t>(k)];
  }

  std::array<bool, kKinds> on_{};  ///< which effects run (at most kMaxEffects)
  std::array<std::array<double, kMaxEffectParams>, kKinds> p_{};
  OddPolynomial f_;
  double x_sat_ = 1e300;
  bool saturate_drive_ = false;  ///< the saturation acts on G's input (on_drive), not on the displacement
  double Ts_ = 1e-3;
  // Linear block (G, G with a creep branch, or G times a mode), discretised for
  // a grid of time scales when the effect changes the time scale.
  /// Per grid entry, [A | B] row-major, as linear_step reads it.
  std::vector<std::array<double, kMaxOrder*(kMaxOrder + 1)>> AB_grid_;
  /// Per grid entry, E = e^{A (1 - d) Ts} int_0^{d Ts} e^{A s} ds B: the drive the previous held value gives over
  /// the first d of a sample, d the delay's fraction (zero without one).
  std::vector<std::array<double, kMaxOrder>> E_grid_;
  double w_previous_ = 0.0;  ///< the drive of the held value before the current one (fractional delay)
  /// The grid: a row per direction (asymmetric dynamics: rising, then relaxing; else one), each of grid_columns_
  /// bias time scales (bias-dependent dynamics: 41; else one). Entry row * grid_columns_ + column.
  size_t grid_columns_ = 1;
  std::array<double, kMaxOrder> C_{};
  double D_ = 0.0;
  std::array<double, kMaxOrder> x_{};
  /// The rest state at time scale 1, x = (I - A)^-1 B w: (I - A) factorised once, B.
  Eigen::PartialPivLU<Matrix> rest_lu_;
  Vector rest_B_;
  LinearStep linear_step_ = nullptr;
  double dc_gain_ = 0.0, y_ref_ = 1.0;
  double inverse_y_ref_ = 1.0;  ///< a product on the state's chain, not a division (latency)
  /// The linear block's own DC gain (G's with creep's slow gain): what y_lin_ settles to per unit drive, the
  /// target asymmetric dynamics compare it with.
  double block_dc_gain_ = 0.0;
  /// The delayed commands, a power of two long (at least the whole delay plus two, sized at construction).
  std::vector<double> delay_line_;
  size_t head_ = 0;
  int delay_whole_ = 1;          ///< the I/O delay plus the delay effect, in samples: whole part
  double delay_fraction_ = 0.0;  ///< and the fraction (where in a sample the held command switches)
  std::array<double, kPlays> plays_{};
  std::array<double, kPlays> play_r_{};  ///< the hysteresis effect's play thresholds
  double slew_state_ = 0.0;
  double loop_memory_ = 0.0;  ///< see set_loop_memory
  long sample_ = 0;
  double y_lin_ = 0.0, y_ = 0.0;
  double y_op_ = 0.0, op_gain_ = 1.0;  ///< operating point (low-passed displacement) for bias-dependent dynamics
  double swing_ = 0.0;                 ///< low-passed |y - y_op|: the motion's amplitude about it
};

}  // namespace pvcgel::control
