#pragma once
/// @file
/// Reference feedforward through the exact, stable inverse of the sampled G.

#include "control/hammerstein_model.hpp"
#include "control/lti_filter.hpp"

namespace pvcgel::control {

/// `v_ff[k] = A(z)/B(z) r[k + r]`: the linear-block input that makes the
/// nominal sampled model output exactly the reference. G is minimum phase and
/// its sampled zeros are checked inside the unit circle, so the inverse is
/// stable; it is proper in z because it reads the reference r samples ahead
/// (r = hold delay + I/O delay), which the trajectory source provides.
class ReferenceFeedforward final {
 public:
  ReferenceFeedforward() = default;
  explicit ReferenceFeedforward(const DiscretePlantModel& plant)
      : inverse_(realize(plant.inverse)), preview_(plant.delay_samples) {}

  /// Samples of reference preview this filter needs.
  [[nodiscard]] int preview_samples() const noexcept { return preview_; }
  /// Feedforward for this sample given r[k + preview_samples()]. Real-time safe.
  double step(double r_ahead_um) noexcept { return v_ff_ = inverse_.step(r_ahead_um); }
  /// Latest output.
  [[nodiscard]] double value() const noexcept { return v_ff_; }
  /// Steady state for a constant reference.
  void reset_steady_state(double r_um) noexcept { inverse_.reset_steady_state(r_um); }

 private:
  LtiFilter inverse_;
  int preview_ = 1;
  double v_ff_ = 0.0;
};

}  // namespace pvcgel::control
