#pragma once
/// @file
/// Allocation-free runtime form of a discrete SISO LTI system.

#include <Eigen/Core>

#include "control/state_space.hpp"

namespace pvcgel::control {

/// Runs `x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k]` with fixed-capacity
/// Eigen storage (no heap), so it may live on the real-time path.
class LtiFilter final {
 public:
  /// Largest order supported.
  static constexpr int kMaxOrder = 10;

  LtiFilter() = default;
  /// @throws ConfigError if the model has more than kMaxOrder states.
  explicit LtiFilter(const StateSpace& discrete);

  /// Output for input u, then advance the state. Real-time safe.
  double step(double u) noexcept {
    const double y = C_.dot(x_) + D_ * u;
    x_ = A_ * x_ + B_ * u;
    return y;
  }
  /// Output the next step will produce for input u, without advancing.
  [[nodiscard]] double peek(double u) const noexcept { return C_.dot(x_) + D_ * u; }
  /// Put the filter at the steady state for constant input u (no transient);
  /// for filters with a pole at z = 1 the state is zeroed instead.
  void reset_steady_state(double u) noexcept { x_ = steady_state_per_unit_input_ * u; }
  /// Zero the state.
  void reset() noexcept { x_.setZero(); }
  /// Steady-state gain; NaN when the filter has a pole at z = 1.
  [[nodiscard]] double dc_gain() const noexcept { return dc_gain_; }
  /// Number of states.
  [[nodiscard]] int order() const noexcept { return static_cast<int>(x_.size()); }

 private:
  using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxOrder, kMaxOrder>;
  using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxOrder, 1>;
  using RowVector = Eigen::Matrix<double, 1, Eigen::Dynamic, Eigen::RowMajor, 1, kMaxOrder>;
  Matrix A_;
  Vector B_, x_, steady_state_per_unit_input_;
  RowVector C_;
  double D_ = 0.0;
  double dc_gain_ = 0.0;
};

}  // namespace pvcgel::control
