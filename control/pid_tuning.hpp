#pragma once
/// @file
/// Reproducible PID tuning for a target crossover frequency and phase margin.

#include <complex>

#include "control/pid.hpp"
#include "control/state_space.hpp"

namespace pvcgel::control {

/// What "well tuned" means, so that every controller mode is tuned the same way.
struct TuningTarget {
  double crossover_rad_s = 60.0;   ///< open-loop gain crossover
  double phase_margin_deg = 60.0;  ///< phase margin at that crossover
  double derivative_ratio = 0.25;  ///< Td / Ti (Ziegler-Nichols' ratio)
  double derivative_filter_n = 10.0;  ///< tf = Td / N (at least one sample)
};

/// Margins of a discrete loop, read off its frequency response.
struct LoopMargins {
  double crossover_rad_s = 0.0;   ///< first frequency where |L| falls through 1
  double phase_margin_deg = 0.0;
  double gain_margin_db = 0.0;    ///< +inf when the phase never reaches -180 deg
  double max_closed_loop_pole_abs = 0.0;  ///< spectral radius of the closed loop
  [[nodiscard]] bool stable() const noexcept { return max_closed_loop_pole_abs < 1.0; }
};

/// A tuned controller and what it achieves on the design plant.
struct TuningResult {
  PidGains gains;
  LoopMargins margins;
};

/// Tunes `kp (1 + 1/(Ti s) + Td s / (Td/N s + 1))` with Td = ratio * Ti so that
/// |C P| = 1 and arg(C P) = -180 deg + PM at the target crossover, on the discrete
/// plant P (ZOH, delays included) and with the discrete PID Pid runs. Of the
/// integral times that meet the phase condition, it takes the smallest (most
/// integral action: the references are slow sinusoids).
/// @throws ConfigError (key "controller.tuning") when no PID of the family meets the target.
TuningResult tune_pid(const DiscreteTransferFunction& plant, double Ts_s, const TuningTarget& target);

/// Margins and closed-loop poles of the unity-feedback loop C P.
LoopMargins loop_margins(const DiscreteTransferFunction& controller,
                         const DiscreteTransferFunction& plant, double Ts_s);

/// Roots of the closed-loop characteristic polynomial a_C a_P + b_C b_P.
Eigen::VectorXcd closed_loop_poles(const DiscreteTransferFunction& controller,
                                   const DiscreteTransferFunction& plant);

}  // namespace pvcgel::control
