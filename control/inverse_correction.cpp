#include "control/inverse_correction.hpp"

#include <cmath>

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {
constexpr double kInitialCovariance = 1.0;
constexpr double kMaxCovarianceTrace = 1e3;  // stops covariance wind-up without excitation
}  // namespace

InverseCorrection::InverseCorrection(const DisturbanceObserver& dob, const DiscretePlantModel& plant,
                                     double w_lower, double w_upper, double memory_s) {
  if (!(memory_s > 10.0 * plant.Ts_s))
    throw ConfigError("controller.feedforward.learning_memory_s", "must exceed 10 samples");
  const auto regressor_filter = realize(dob.q().delayed(plant.delay_samples));
  feature_z_ = LtiFilter(regressor_filter);
  feature_z2_ = LtiFilter(regressor_filter);
  scale_ = std::max(std::abs(w_upper), 1e-12);
  z_lo_ = w_lower / scale_;
  z_hi_ = w_upper / scale_;
  forgetting_ = 1.0 - plant.Ts_s / memory_s;
  P_ = Eigen::Matrix3d::Identity() * kInitialCovariance;
}

void InverseCorrection::reset_steady_state(double w0) noexcept {
  const double z = w0 / scale_;
  feature_z_.reset_steady_state(z);
  feature_z2_.reset_steady_state(z * z);
  theta_ << 0.0, 1.0, 0.0;
  P_ = Eigen::Matrix3d::Identity() * kInitialCovariance;
}

void InverseCorrection::update(double target) noexcept {
  if (!std::isfinite(target)) return;
  const Eigen::Vector3d phi(1.0, feature_z_.peek(0.0), feature_z2_.peek(0.0));
  const double t = target / scale_;
  const Eigen::Vector3d Pphi = P_ * phi;
  const double denom = forgetting_ + phi.dot(Pphi);
  const Eigen::Vector3d gain = Pphi / denom;
  const Eigen::Vector3d theta = theta_ + gain * (t - phi.dot(theta_));
  Eigen::Matrix3d P = P_ - gain * Pphi.transpose();
  if (P.trace() < kMaxCovarianceTrace) P /= forgetting_;
  P_ = 0.5 * (P + P.transpose());
  // p'(z) = theta1 + 2 theta2 z is linear in z: increasing on the range iff at both ends.
  const bool monotone = theta(1) + 2.0 * theta(2) * z_lo_ > 0.0 && theta(1) + 2.0 * theta(2) * z_hi_ > 0.0;
  if (monotone && theta.allFinite() && theta(1) > 0.2 && theta(1) < 5.0) theta_ = theta;
}

double InverseCorrection::inverse(double v) const noexcept {
  const double c = theta_(0) - v / scale_;
  const double a = theta_(2), b = theta_(1);
  const double disc = b * b - 4.0 * a * c;
  if (disc <= 0.0) return scale_ * (-b / (2.0 * a));  // beyond p's extremum: its nearest point
  // Citardauq form: stable for a -> 0 and picks the increasing branch.
  return scale_ * (-2.0 * c / (b + std::sqrt(disc)));
}

}  // namespace pvcgel::control
