#pragma once
/// @file
/// The paper's disturbance observer (Fig. 4), exact in discrete time.

#include <optional>

#include "control/hammerstein_model.hpp"
#include "control/lti_filter.hpp"

namespace pvcgel::control {

/// Estimates the lumped input disturbance d of the linear block (imperfect
/// inversion, unmodelled dynamics, physical disturbances):
/// `d_hat = Q [ G^-1 y ] - Q [ v ]`, with Q(s) = 1 / (lambda s + 1)^m.
/// G^-1 is the causal exact inverse of the sampled G (ZOH plus I/O delay), so
/// the estimate is the disturbance r samples ago filtered by Q, with no
/// half-sample error from approximating the hold; v is delayed to match.
class DisturbanceObserver final {
 public:
  DisturbanceObserver() = default;
  /// @param lambda_s  Q's time constant (paper: 0.1 s)
  /// @param q_order  m, Q's relative degree
  /// @throws ConfigError (key "controller.dob.*") if lambda is not positive or
  ///         the continuous Q G^-1 is improper (m below G's relative degree).
  DisturbanceObserver(const HammersteinModel& model, const DiscretePlantModel& plant,
                      double lambda_s, int q_order = 1);

  /// d_hat for this sample from the measurement y (um). Real-time safe.
  double estimate(double y_um) noexcept {
    filtered_input_ = from_output_.step(y_um);
    return d_hat_ = filtered_input_ - from_input_.peek(0.0);
  }
  /// Report the linear-block input actually applied this sample (after clamping).
  void commit(double v_applied) noexcept { from_input_.step(v_applied); }
  /// Steady state for a constant applied input v0 on the nominal model (d_hat = 0).
  void reset_steady_state(double v0, double dc_gain) noexcept {
    from_output_.reset_steady_state(v0 * dc_gain);
    from_input_.reset_steady_state(v0);
  }
  /// Latest estimate.
  [[nodiscard]] double d_hat() const noexcept { return d_hat_; }
  /// Q [G^-1 y]: the filtered estimate of the linear block's true input.
  [[nodiscard]] double filtered_input() const noexcept { return filtered_input_; }
  /// The discrete Q(z) (Tustin), for filters that must see the same Q.
  [[nodiscard]] const DiscreteTransferFunction& q() const noexcept { return q_; }
  /// Q(s) G^-1(s), the continuous filter of the paper (checked proper and stable).
  [[nodiscard]] const TransferFunction& q_g_inverse() const noexcept { return *qginv_; }

 private:
  DiscreteTransferFunction q_;
  std::optional<TransferFunction> qginv_;
  LtiFilter from_output_, from_input_;
  double d_hat_ = 0.0, filtered_input_ = 0.0;
};

}  // namespace pvcgel::control
