#pragma once
/// @file
/// The candidate effects of `pvcgel diagnose`: small, physically meaningful
/// augmentations of the Hammerstein model, and a plant that runs the model
/// with one of them (the form that is fitted to recordings and that the
/// simulated rig runs after a diagnosis).

#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "control/hammerstein_model.hpp"

namespace pvcgel::control::diagnosis {

/// What the nominal model may be missing.
enum class EffectKind {
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
std::string_view to_string(EffectKind kind) noexcept;
/// Inverse of to_string.
std::optional<EffectKind> parse_effect_kind(std::string_view name) noexcept;

/// One physical parameter of an effect.
struct ParameterSpec {
  std::string name;         ///< key in files and JSON, with its unit (e.g. "time_constant_s")
  double lower = 0.0;       ///< bounds the fit respects
  double upper = 0.0;
  bool log_scale = false;   ///< fitted in log space (positive scale parameters)
  std::vector<double> starts;  ///< coarse grid of starting values for the fit
};

/// Length of the plant's delay line (io delay plus the delay effect, in samples).
inline constexpr int kDelayLineSamples = 256;

/// Maximum number of parameters of one effect.
inline constexpr int kMaxEffectParams = 3;

/// An effect with its parameters (meaning per kind: see parameter_specs()).
struct Effect {
  EffectKind kind = EffectKind::none;
  std::array<double, kMaxEffectParams> p{};
};

/// Parameters of `kind` with bounds and fit starts. `sample_time_s` and
/// `duration_s` (the longest recording) set the bounds that depend on them.
std::vector<ParameterSpec> parameter_specs(EffectKind kind, double sample_time_s, double duration_s);

/// One sentence on what the effect is, in physical terms.
std::string_view physical_meaning(EffectKind kind) noexcept;

/// Checks parameters against their bounds. @throws ConfigError naming `key`.
void validate(const Effect& effect, double sample_time_s, const std::string& key);

/// The Hammerstein model with at most one added effect, stepped with the
/// daemon's convention: output() is the displacement at the start of cycle k,
/// apply(u) holds u over the cycle and advances one sample. The nominal model
/// (EffectKind::none) is exactly SimulatedRig without sensor effects.
/// Candidate forms (the generator in generator.hpp uses different ones):
///  - hysteresis: Prandtl-Ishlinskii play operators on the voltage,
///    x = u - alpha mean_i(u - play_{r_i}(u)), r_i = R i / 8;
///  - creep: one Kelvin-Voigt branch fraction G(0) / (tau s + 1) in parallel with G;
///  - dead_zone: no response below threshold d, linear catch-up to u at 2 d;
///  - saturation: y above a knee softens as knee + e / sqrt(1 + (e / Y)^2);
///  - delay: extra transport delay (fractional, linear interpolation);
///  - asymmetric_dynamics: G runs (1 + kappa) times slower while relaxing;
///  - slew_limit: the amplifier voltage changes at most S V/s;
///  - resonance: a structural mode w_n^2 / (s^2 + 2 zeta w_n s + w_n^2) in series;
///  - drift: offset + rate max(t - onset, 0), independent of the input;
///  - bias_dependent_dynamics: G runs (1 + beta y / y_ref) times slower,
///    y_ref = G(0) f(500 V).
/// Construction allocates; reset and stepping do not.
class AugmentedPlant final {
 public:
  /// @throws ConfigError if G is unstable or improper, or parameters are out of bounds.
  AugmentedPlant(const HammersteinModel& model, int io_delay_samples, double sample_time_s, const Effect& effect);

  /// At rest under constant u (play operators virgin, time zero).
  void reset_steady_state(double u_V) noexcept;
  /// Displacement now (start of the current cycle).
  [[nodiscard]] double output() const noexcept { return y_; }
  /// Hold u for this cycle and advance one sample.
  void apply(double u_V) noexcept;

  /// The voltage at which this plant rests with output y (bisection over
  /// [lo, hi]; the nearer end when y is out of reach). Leaves the plant at rest there.
  double rest_voltage(double y_um, double lo_V, double hi_V) noexcept;

  /// Output-error simulation: at rest at `initial_V`, then y[k] for every u[k].
  std::vector<double> simulate(const std::vector<double>& u_V, double initial_V);

 private:
  static constexpr int kMaxOrder = 6;
  static constexpr int kPlays = 8;
  static constexpr int kDelayLine = kDelayLineSamples;
  using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxOrder, kMaxOrder>;
  using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxOrder, 1>;
  using RowVector = Eigen::Matrix<double, 1, Eigen::Dynamic, Eigen::RowMajor, 1, kMaxOrder>;

  [[nodiscard]] double nonlinearity(double x_V) const noexcept { return f_(std::min(x_V, x_sat_)); }
  [[nodiscard]] double output_stage(double y_lin, long sample) const noexcept;
  [[nodiscard]] double time_scale(double w) const noexcept;

  Effect e_;
  OddPolynomial f_;
  double x_sat_ = 1000.0;
  double Ts_ = 1e-3;
  int io_delay_ = 1;
  // Linear block (G, G with a creep branch, or G times a mode), discretised for
  // a grid of time scales when the effect changes the time scale.
  std::vector<Matrix> A_grid_;
  std::vector<Vector> B_grid_;
  std::vector<double> scale_grid_;
  RowVector C_;
  double D_ = 0.0;
  Vector x_;
  double dc_gain_ = 0.0, y_ref_ = 1.0;
  std::array<double, kDelayLine> delay_line_{};
  int head_ = 0;
  std::array<double, kPlays> plays_{};
  double slew_state_ = 0.0;
  long sample_ = 0;
  double y_lin_ = 0.0, y_ = 0.0;
  double y_op_ = 0.0, op_gain_ = 1.0;  ///< operating point (low-passed displacement) for bias-dependent dynamics
};

}  // namespace pvcgel::control::diagnosis
