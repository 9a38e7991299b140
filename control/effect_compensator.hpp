#pragma once
/// @file
/// Compensation of the effects a model file carries (`[[model.effect]]`, the
/// format of `[[sim.truth.effect]]`): the inverses the controller's f^-1 path
/// runs, in the forms AugmentedPlant (effect.hpp) defines.

#include <array>
#include <span>
#include <string>

#include "control/effect.hpp"
#include "control/hammerstein_model.hpp"

namespace pvcgel::control {

/// The hysteresis effect's Prandtl-Ishlinskii operator and its exact inverse.
///
/// Forward (effect.hpp): H[x] = x - alpha mean_i(x - P_i[x]) = a0 x + sum_i a_i P_i[x],
/// a0 = 1 - alpha, a_i = alpha / N, P_i the play with threshold r_i (ascending).
/// Its slope is a0 right after a reversal and grows to 1 as plays start to move.
/// The inverse is again a PI operator (Kuhnen's closed form), on the output h:
///   x = h / a0 + sum_i b_i Q_i[h],  Q_i a play with threshold
///   s_i = sum_{j<i} a_j (r_i - r_j)          (j = 0 is a0 with r_0 = 0),
///   b_i = -a_i / (A_i A_{i-1}),   A_i = a0 + sum_{j<=i} a_j,
/// and its play states follow from the forward ones (same reversal history):
///   q_i = A_{i-1} p_i + sum_{j>=i} a_j p_j.
/// Only the forward plays are stored: the inverse reads them, so whatever
/// voltage is finally applied (clamped, slew-limited) is what `commit` records.
class HysteresisOperator final {
 public:
  HysteresisOperator() = default;
  /// @param alpha  in [0, 1); @param threshold_scale_V  R > 0; @param threshold_spread  the loop's shape
  /// (r_i = play_thresholds(R, spread), ascending for every spread: the inverse below holds for all)
  HysteresisOperator(double alpha, double threshold_scale_V, double threshold_spread = 0.0) noexcept;

  /// H[x] from the current state, without advancing it.
  [[nodiscard]] double forward(double x_V) const noexcept;
  /// The x with forward(x) == h, from the current state (exact, no iteration).
  [[nodiscard]] double inverse(double h_V) const noexcept;
  /// Advance the plays with the input actually applied.
  void commit(double x_V) noexcept;
  /// Virgin state at rest under x (every play at x, H[x] = x).
  void reset(double x_V) noexcept { plays_.fill(x_V); }

 private:
  static constexpr int kN = kHysteresisPlays;
  std::array<double, kN> r_{}, plays_{}, s_{}, b_{}, prefix_{};  // prefix_[i] = A_{i-1}
  double a0_ = 1.0, a_ = 0.0;
};

/// Everything the controller compensates beyond the Hammerstein model, from a
/// model file's `[[model.effect]]` list. How each effect is compensated:
///  - hysteresis, dead zone, slew limit (input side, on the voltage): exact
///    inverses, applied after f^-1 in the order opposite to the plant's
///    (plant: slew limit -> dead zone -> hysteresis -> f), with the states
///    (plays, amplifier ramp) advanced by the voltage actually applied;
///  - saturation on the drive (on_drive): between f and G, its exact inverse
///    (drive_inverse) taken on the linear block's input before f^-1;
///  - saturation and drift (output side): reference and measurement are both
///    mapped to the linear block's output, y_lin = sat^-1(y - drift(t)), so the
///    PID, the DOB and the feedforward work on the model they were designed
///    for; drift is a known additive term (feedforward through the reference),
///    its time counted from the controller's last reset_steady_state (its wander,
///    a random walk, is no known term: the feedback meets it as a disturbance);
///  - creep: a known additive term, predicted online: its Kelvin-Voigt branches
///    (effect.hpp) run on the linear block's input actually applied, delayed as
///    the plant delays it, and their output is subtracted from measurement and
///    reference (the preview's samples predicted that far ahead). The loop then
///    sees G alone; the feedforward, fed r - creep, inverts G + creep in effect
///    (a feedback around G^-1 with loop gain fraction G(0) / (G(s) (tau s + 1)):
///    the fraction at DC, falling beyond the creep's corner for the gel's G).
///    Folding creep into G instead was tried: the sampled G + creep has a zero
///    within 1e-4 of its creep pole near z = 1, which the discrete inverse's
///    design check cannot place reliably (it saw z = 1.0004 for 5% at 10 s);
///  - resonance: folded into the linear model (linear_model), so the feedforward
///    and the DOB invert it when the design checks (sampled zeros inside the unit
///    circle, proper Q G^-1, closed-loop stability) accept it; otherwise refused;
///  - delay: the whole samples join the sampled model's delay (more reference
///    preview, the DOB delays its input to match); the fraction of a sample is
///    read between two preview samples.
/// Refused at construction, with the reason (ConfigError naming model.effect[i]):
/// asymmetric and bias-dependent dynamics (their inverse is a state-dependent G^-1
/// that this controller does not implement; the DOB rejects them as a disturbance
/// if the effect is dropped from the file), and effects whose inverse would not
/// be safe within the voltage limits (see the constructor).
/// Real-time: every method used per cycle is allocation-, exception- and lock-free.
class EffectCompensator final {
 public:
  EffectCompensator() = default;
  /// @throws ConfigError naming `model.effect[i]` for an effect that cannot be
  ///         compensated safely: hysteresis alpha >= 0.9 (the inverse would
  ///         multiply voltage steps by 10 or more), a dead zone plus catch-up at or
  ///         above voltage_max_V, a saturation whose inverse gain at the stroke
  ///         of operating_point_um exceeds 4 (the stroke lies deep beyond the knee).
  /// @param io_delay_samples  the sampled model's I/O delay (creep's input is delayed as much, plus a delay effect)
  /// @param operating_point_um  a displacement the loop must work at (the saturation's safety check)
  EffectCompensator(const HammersteinModel& model, std::span<const Effect> effects, double sample_time_s,
                    double voltage_min_V, double voltage_max_V, int io_delay_samples, double operating_point_um);

  /// True when any effect is compensated.
  [[nodiscard]] bool active() const noexcept { return count_ > 0; }
  /// "model.effect[i]" for the effect of this kind (the list's own index).
  [[nodiscard]] std::string key(EffectKind kind) const;
  /// G with the linear effects folded in (a resonance).
  [[nodiscard]] TransferFunction linear_model(const TransferFunction& G) const;
  /// Extra delay beyond the I/O delay: whole samples and the remaining fraction.
  [[nodiscard]] int extra_delay_samples() const noexcept { return delay_whole_; }
  [[nodiscard]] double extra_delay_fraction() const noexcept { return delay_fraction_; }

  /// Input side. What f sees for voltage u now (no state change).
  [[nodiscard]] double effective_input(double u_V) const noexcept;
  /// The voltage for which effective_input(u) == x (within the amplifier's reach).
  [[nodiscard]] double voltage_for(double x_V) const noexcept;
  /// The linear block's input for f's output w: a saturation on the drive, else w.
  [[nodiscard]] double drive(double w) const noexcept;
  /// d drive / dw (1 without a saturation on the drive).
  [[nodiscard]] double drive_slope(double w) const noexcept;
  /// f's output that gives the linear block's input w (drive's inverse; a request beyond the
  /// saturation's ceiling is read as 95% of the way there, as on the output side).
  [[nodiscard]] double drive_inverse(double w) const noexcept;
  /// The voltage at rest that gives effective input x (reset_steady_state).
  [[nodiscard]] double rest_voltage_for(double x_V) const noexcept;
  /// Advance the states with the voltage applied this cycle, w = f(effective_input(u))
  /// the linear block's input it gives (creep), and the drift's clock.
  void commit(double u_applied_V, double w_applied) noexcept;
  /// At rest under u, play operators virgin, drift clock at zero (call reset_creep next).
  void reset_steady_state(double u_V) noexcept;
  /// Creep at rest under the linear block's input w.
  void reset_creep(double w) noexcept;
  /// Creep's share of the DC gain (sum of the branch fractions; 0 without creep).
  [[nodiscard]] double creep_fraction() const noexcept { return creep_fraction_; }
  /// The linear block's input that holds the rig at y_um at rest, now (G(0) given).
  [[nodiscard]] double rest_linear_input(double y_um, double dc_gain) const noexcept {
    return output_side_inverse(y_um, 0.0) / (dc_gain * (1.0 + creep_fraction_));
  }

  /// Output side. The linear block's output that puts the rig at y_um, at
  /// `samples_ahead` cycles from now (for the reference preview).
  [[nodiscard]] double linear_output(double y_um, double samples_ahead = 0.0) const noexcept;

 private:
  [[nodiscard]] bool has(EffectKind k) const noexcept { return index_[static_cast<size_t>(k)] >= 0; }
  [[nodiscard]] const std::array<double, kMaxEffectParams>& p(EffectKind k) const noexcept {
    return p_[static_cast<size_t>(k)];
  }
  [[nodiscard]] bool slew_digital() const noexcept { return p(EffectKind::slew_limit)[1] != 0.0; }
  [[nodiscard]] double slew_forward(double u_V) const noexcept;
  [[nodiscard]] double slew_inverse(double x_V) const noexcept;
  /// The saturation's inverse on a displacement (output side) or a static displacement G(0) w (the drive).
  [[nodiscard]] double saturation_inverse(double y_um) const noexcept;
  /// S^-1(y - drift) at `ahead` samples from now.
  [[nodiscard]] double output_side_inverse(double y_um, double ahead) const noexcept;
  /// Predicted creep output `ahead` whole samples from now.
  [[nodiscard]] double creep_ahead(int ahead) const noexcept;
  void refuse_unsafe(double voltage_max_V, double operating_point_um) const;

  static constexpr size_t kKinds = kEffectKindNames.size();
  std::array<int, kKinds> index_ = [] {
    std::array<int, kKinds> a{};
    a.fill(-1);  // -1: the kind is not compensated
    return a;
  }();
  std::array<std::array<double, kMaxEffectParams>, kKinds> p_{};
  std::array<Effect, kKinds> effects_{};
  int count_ = 0;
  HysteresisOperator hysteresis_;
  double Ts_ = 1e-3;
  double slew_state_V_ = 0.0, slew_step_V_ = 0.0;
  double drive_dc_gain_ = 0.0;  ///< G(0) when the saturation acts on the drive, else 0
  int delay_whole_ = 0;
  double delay_fraction_ = 0.0;
  long sample_ = 0;
  // Creep: up to three first-order branches x <- a x + (1 - a) g w[k - delay], w's history.
  static constexpr int kMaxCreepBranches = 3, kHistory = 32;
  std::array<double, kMaxCreepBranches> creep_a_{}, creep_g_{}, creep_x_{};
  int creep_branches_ = 0, creep_delay_ = 0;
  double creep_fraction_ = 0.0;
  std::array<double, kHistory> w_history_{};
  int w_head_ = 0;  ///< where the next w goes
};

}  // namespace pvcgel::control
