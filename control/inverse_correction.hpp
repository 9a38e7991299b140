#pragma once
/// @file
/// Online correction of the static nonlinearity the inverse compensator uses.

#include <Eigen/Core>

#include "control/disturbance_observer.hpp"
#include "control/lti_filter.hpp"

namespace pvcgel::control {

/// Learns `w_true = p(f(x))`, a monotone quadratic p that maps what the model's
/// f predicts onto what the rig's linear block actually receives, by recursive
/// least squares with forgetting on signals the disturbance observer already
/// has: its filtered estimate Q[G^-1 y] of the true input, against Q z^-r of
/// the features [1, f(x), f(x)^2]. Filtering both sides with the same Q z^-r
/// keeps the regression exact under any input, not only in steady state.
/// The inverse then solves p(f(x)) = v. This removes the static part of the
/// inversion error (for the paper rig, the n = 2 model's gain is about 27%
/// below the n = 3 truth), which the DOB alone rejects only within Q's bandwidth.
/// Updates that would make p non-monotone over the voltage range are refused.
class InverseCorrection final {
 public:
  InverseCorrection() = default;
  /// @param w_scale  normalisation of f's output (f at the upper voltage limit)
  /// @param w_range  [f(lower), f(upper)]: where p must stay increasing
  /// @param memory_s  forgetting time constant
  InverseCorrection(const DisturbanceObserver& dob, const DiscretePlantModel& plant, double w_lower,
                    double w_upper, double memory_s);

  /// Update from the DOB's current filtered input estimate. Real-time safe.
  void update(double filtered_true_input) noexcept;
  /// Report the model output f(x) for the voltage applied this sample.
  void commit(double f_applied) noexcept {
    const double z = f_applied / scale_;
    feature_z_.step(z);
    feature_z2_.step(z * z);
  }
  /// p(w): corrected linear-block input for a model prediction w = f(x).
  [[nodiscard]] double forward(double w) const noexcept {
    const double z = w / scale_;
    return scale_ * (theta_(0) + z * (theta_(1) + z * theta_(2)));
  }
  /// p^-1(v) on p's increasing branch.
  [[nodiscard]] double inverse(double v) const noexcept;
  /// Coefficients of p in normalised units (identity: [0, 1, 0]).
  [[nodiscard]] const Eigen::Vector3d& theta() const noexcept { return theta_; }
  /// Steady state for constant f output w0 with the identity map.
  void reset_steady_state(double w0) noexcept;

 private:
  LtiFilter feature_z_, feature_z2_;
  Eigen::Vector3d theta_{0.0, 1.0, 0.0};
  Eigen::Matrix3d P_ = Eigen::Matrix3d::Identity();
  double scale_ = 1.0, z_lo_ = 0.0, z_hi_ = 1.0, forgetting_ = 1.0;
};

}  // namespace pvcgel::control
