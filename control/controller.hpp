#pragma once
/// @file
/// The tracking controller: inverse compensator, PID, disturbance observer,
/// reference feedforward and output stage, in the paper's structure (Fig. 4).

#include <array>
#include <cstdint>
#include <optional>
#include <utility>
#include <span>
#include <string_view>
#include <vector>

#include "control/disturbance_observer.hpp"
#include "control/effect_compensator.hpp"
#include "control/enum_table.hpp"
#include "control/hammerstein_model.hpp"
#include "control/inverse_correction.hpp"
#include "control/output_stage.hpp"
#include "control/pid.hpp"
#include "control/pid_tuning.hpp"
#include "control/polynomial_inverse.hpp"
#include "control/reference_feedforward.hpp"

namespace pvcgel::control {

/// The paper's three controllers and one beyond it.
enum class ControllerMode : std::uint8_t {
  pid,                 ///< PID on the voltage directly
  inverse_pid,         ///< PID through the inverse compensator f^-1
  inverse_pid_dob,     ///< ... plus the disturbance observer
  inverse_pid_dob_ff,  ///< ... plus reference feedforward through G^-1 and a learned inverse correction
};
inline constexpr std::array<ControllerMode, 4> kAllModes{ControllerMode::pid, ControllerMode::inverse_pid,
                                                         ControllerMode::inverse_pid_dob,
                                                         ControllerMode::inverse_pid_dob_ff};
inline constexpr auto kControllerModeNames = enum_table<ControllerMode::pid, ControllerMode::inverse_pid_dob_ff>(
    {"pid", "inverse_pid", "inverse_pid_dob", "inverse_pid_dob_ff"});
constexpr const auto& names_of(ControllerMode) noexcept { return kControllerModeNames; }
/// "pid", "inverse_pid", ...
constexpr std::string_view to_string(ControllerMode m) noexcept { return kControllerModeNames.to_string(m); }
/// Inverse of to_string.
std::optional<ControllerMode> parse_mode(std::string_view name) noexcept;

/// Reference samples beyond r[k] pvcgeld's loop can provide.
inline constexpr int kMaxPreviewSamples = 15;

/// Everything the controller needs besides the model. Checked by the constructor.
struct ControllerConfig {
  double sample_time_s = 1e-3;
  int io_delay_samples = 1;  ///< I/O delay of the rig beyond the zero-order hold
  ControllerMode mode = ControllerMode::inverse_pid_dob;
  double voltage_min_V = 0.0;
  double voltage_max_V = 1000.0;
  double slew_limit_V_per_s = 0.0;  ///< 0: off
  double dob_lambda_s = 0.1;
  int dob_q_order = 1;
  double learning_memory_s = 4.0;  ///< forgetting time of the inverse correction (ff mode)
  /// When set, every mode's PID is tuned to this target on the plant that mode sees;
  /// otherwise `gains` are used as given.
  std::optional<TuningTarget> tuning = TuningTarget{};
  std::array<PidGains, 4> gains{};  ///< indexed by ControllerMode
  double operating_point_um = 100.0;  ///< where mode pid's plant is linearised for tuning
  /// Small-signal gain of the real plant relative to the model, per mode, as a
  /// frequency-response measurement on the rig shows it (1: trust the model).
  /// Tuning on what the loop really sees is what makes modes comparable.
  std::array<double, 4> tuning_gain_scale{1.0, 1.0, 1.0, 1.0};
  double antiwindup_tracking_time_s = 0.0;  ///< 0: automatic
  /// Effects the model carries (`[[model.effect]]`, dominant first), compensated
  /// by the inverse modes (EffectCompensator says how; some are refused).
  std::vector<Effect> effects{};
  /// Most reference samples beyond r[k] the caller can give (pvcgeld's preview
  /// buffer holds 16 samples: r[k] and 15 ahead); a delay needing more is refused.
  int max_preview_samples = kMaxPreviewSamples;
};

/// Result of one controller step.
struct ControlOutput {
  enum class Status : std::uint8_t { ok, saturated, invalid_input };
  double voltage_V = 0.0;      ///< to the amplifier (clamped, slew-limited)
  double unclamped_V = 0.0;    ///< what the control law asked for
  double v_command = 0.0;      ///< linear-block input requested (inverse modes)
  double d_hat = 0.0;          ///< disturbance estimate (linear-block input units)
  double v_ff = 0.0;           ///< feedforward term
  double error_um = 0.0;       ///< r - y
  Status status = Status::ok;
};

/// One controller instance, any of the four modes, switchable bumplessly.
/// Construction validates and designs everything (may throw ConfigError);
/// `step()` is real-time safe: no allocation, no exceptions, no locks, no I/O.
///
/// Signals (paper Fig. 4): y measured, r the reference, G_d the sampled linear
/// model with its delay r_d, f the static nonlinearity, C the PID. With effects
/// (`[[model.effect]]`, EffectCompensator) the loop works on the linear block's
/// output, r_lin = S^-1(r - drift) - creep, y_lin = S^-1(y - drift) - creep (S the
/// saturation, creep predicted from the applied input; identities without those
/// effects), e = r_lin - y_lin; H is the input-side chain (slew limit, dead zone,
/// hysteresis; identity without them); G_d includes a resonance with a direct
/// fraction and whole samples of extra delay.
///  - pid:                u = C e. No model inverse, so the input-side effects are
///                        not compensated (by design: it is the paper's baseline); its
///                        tuning plant (drive o f)'(u_op) G_d includes a resonance, the delay and
///                        a saturation on the drive's slope there.
///  - inverse_pid:        v = C e,                    u = H^-1(f^-1(v)).
///  - inverse_pid_dob:    v = C e - d_hat,            u = H^-1(f^-1(v)),
///                        d_hat = Q[G_d^-1 y_lin] - Q[z^-r_d v_applied].
///  - inverse_pid_dob_ff: v = C e + v_ff - d_hat,     u = H^-1(f^-1(p^-1(v))),
///                        v_ff = G_d^-1 r_lin[k + r_d] (read between two preview
///                        samples for a fractional extra delay), p the learned
///                        inverse correction (InverseCorrection).
/// In every mode the output stage clamps and slew-limits u; what was applied,
/// mapped back through f(H(u)) (and p), feeds the PID's anti-windup and the DOB.
class Controller final {
 public:
  Controller(const HammersteinModel& model, const ControllerConfig& config);

  /// One sample: reference preview (r[k], r[k+1], ...; the last value is held
  /// if fewer than preview_samples()+1 are given) and measurement y[k].
  ControlOutput step(std::span<const double> reference_preview_um, double y_um) noexcept;
  /// Switch mode; takes effect at the next step without a jump in the output.
  void set_mode(ControllerMode mode) noexcept { pending_mode_ = mode; }
  /// Current mode.
  [[nodiscard]] ControllerMode mode() const noexcept { return mode_; }
  /// Put every state at the nominal steady state for a constant reference r0.
  void reset_steady_state(double r0_um) noexcept;
  /// The voltage actually applied is `V` (a bumpless start from the amplifier's
  /// real output, or the safety envelope overriding the last step): the output
  /// stage's slew limit continues from there.
  void set_applied_voltage(double V) noexcept { output_.reset(V); }
  /// Voltage applied in the last step (or set by reset_steady_state).
  [[nodiscard]] double last_voltage_V() const noexcept { return output_.last_V(); }
  /// Reference samples beyond r[k] the feedforward uses (more with a delay effect).
  [[nodiscard]] int preview_samples() const noexcept {
    return ff_.preview_samples() + (comp_.extra_delay_fraction() > 0.0 ? 1 : 0);
  }
  /// The effects compensated (model.effect).
  [[nodiscard]] const EffectCompensator& compensator() const noexcept { return comp_; }
  /// Gains in use for a mode.
  [[nodiscard]] const PidGains& gains(ControllerMode m) const noexcept {
    return gains_[static_cast<size_t>(m)];
  }
  /// Margins on the design plant for a mode.
  [[nodiscard]] const LoopMargins& margins(ControllerMode m) const noexcept {
    return margins_[static_cast<size_t>(m)];
  }
  /// Linear plant each mode's PID sees (for tuning and stability checks).
  [[nodiscard]] DiscreteTransferFunction design_plant(ControllerMode m) const;
  /// The learned inverse correction (ff mode).
  [[nodiscard]] const InverseCorrection& inverse_correction() const noexcept { return correction_; }
  [[nodiscard]] const ControllerConfig& config() const noexcept { return cfg_; }
  [[nodiscard]] const DiscretePlantModel& plant_model() const noexcept { return plant_; }

 private:
  /// Tunes (or checks) every mode's PID on its design plant.
  void tune_modes();
  /// The plant and the observers' view of the signals for one sample.
  struct Sample {
    double e_lin = 0.0;  ///< r_lin - y_lin, what the PID sees
    double v_ff = 0.0, d_hat = 0.0;
  };
  /// G's input for voltage u now: f after the input-side effects, then a saturation on the drive.
  [[nodiscard]] double drive_for(double voltage_V) const noexcept {
    return comp_.drive(model_.f(comp_.effective_input(voltage_V)));
  }
  [[nodiscard]] double linear_input_for(double voltage_V, ControllerMode m) const noexcept;
  [[nodiscard]] double voltage_for(double v, ControllerMode m) const noexcept;
  /// Terms added to the PID output in mode m (feedforward, minus the DOB's estimate).
  [[nodiscard]] static double law_offset(ControllerMode m, const Sample& s) noexcept;
  /// Runs the observers and the feedforward (every mode, so a switch finds them settled).
  Sample observe(std::span<const double> preview, double y_lin) noexcept;
  /// Applies a pending mode switch without a voltage step.
  void switch_mode_bumpless(const Sample& s) noexcept;
  /// The voltage law of the current mode; fills the output, returns the PID output
  /// and its applied equivalent.
  std::pair<double, double> apply_law(const Sample& s, ControlOutput& out) noexcept;
  /// Reports what was applied to the PID, the DOB, the correction and the compensator.
  void commit(const Sample& s, double c, double applied_equivalent, double voltage_V) noexcept;

  ControllerConfig cfg_;
  EffectCompensator comp_;
  HammersteinModel model_;  ///< f, and G with the linear effects folded in
  DiscretePlantModel plant_;
  PolynomialInverse inverse_;
  DisturbanceObserver dob_;
  ReferenceFeedforward ff_;
  InverseCorrection correction_;
  OutputStage output_;
  Pid pid_;
  std::array<PidGains, 4> gains_{};
  std::array<LoopMargins, 4> margins_{};
  double pid_plant_gain_ = 1.0;  // d drive(f(x)) / dx at the operating point
  ControllerMode mode_;
  ControllerMode pending_mode_;
};

}  // namespace pvcgel::control
