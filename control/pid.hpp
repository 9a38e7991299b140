#pragma once
/// @file
/// Parallel-form PID with filtered derivative and back-calculation anti-windup.

#include "control/state_space.hpp"

namespace pvcgel::control {

/// Gains of `C(s) = kp + ki / s + kd s / (tf s + 1)`. Units follow the loop:
/// error in micrometres, output in volts (mode `pid`) or in the linear block's
/// input units (inverse modes).
struct PidGains {
  double kp = 0.0;
  double ki = 0.0;    ///< 1/s
  double kd = 0.0;    ///< s
  double tf_s = 0.0;  ///< derivative filter time constant (>= one sample when kd != 0)
};

/// Discrete PID exactly as Pid runs it: forward-Euler integrator, Tustin
/// derivative filter. Used by the tuner and the closed-loop stability check so
/// design and runtime cannot disagree.
DiscreteTransferFunction pid_transfer_function(const PidGains& g, double Ts_s);

/// Real-time PID. The caller computes the unclamped command from `output()`,
/// clamps it, and reports both through `commit()`: the integrator then tracks
/// the clamped value (back-calculation), so saturation never winds it up.
class Pid final {
 public:
  Pid() = default;
  /// @param tracking_time_s  back-calculation time constant; 0 picks sqrt(Ti Td) (or Ti)
  Pid(const PidGains& gains, double Ts_s, double tracking_time_s = 0.0);

  /// Controller output for error e at this sample (does not change the integrator).
  [[nodiscard]] double output(double e) noexcept;
  /// Advance the integrator with the unclamped and the actually applied command.
  void commit(double e, double unclamped, double applied) noexcept;
  /// Bumpless transfer: set the integrator so `output(e)` equals `target` now.
  void align(double e, double target) noexcept;
  /// Switch gains (the filtered derivative of e is gain-independent and kept).
  void set_gains(const PidGains& gains) noexcept;
  /// Zero all state.
  void reset() noexcept;

  /// Current gains.
  [[nodiscard]] const PidGains& gains() const noexcept { return g_; }
  /// Integrator contribution to the output.
  [[nodiscard]] double integral() const noexcept { return integral_; }

 private:
  PidGains g_{};
  double Ts_ = 1e-3;
  double tracking_gain_ = 0.0;  // Ts / Tt
  double fixed_tracking_time_ = 0.0;
  double integral_ = 0.0;
  double e_prev_ = 0.0, dfilt_ = 0.0;      // committed derivative state
  double dfilt_now_ = 0.0;                 // derivative for the current sample
  double a_d_ = 0.0, b_d_ = 0.0;           // Tustin derivative filter coefficients
};

}  // namespace pvcgel::control
