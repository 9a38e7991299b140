#include "control/pid.hpp"

#include <algorithm>
#include <cmath>

namespace pvcgel::control {

DiscreteTransferFunction pid_transfer_function(const PidGains& g, double Ts) {
  // kp + ki Ts z^-1 / (1 - z^-1) + kd * Tustin(s / (tf s + 1)), over a common denominator.
  auto conv = [](const Eigen::VectorXd& x, const Eigen::VectorXd& y) {
    const Eigen::VectorXd one = Eigen::VectorXd::Ones(1);
    return (DiscreteTransferFunction{x, one} * DiscreteTransferFunction{y, one}).b;
  };
  Eigen::VectorXd bi = Eigen::VectorXd::Zero(1), ai = Eigen::VectorXd::Ones(1);
  if (g.ki != 0.0) {  // without I, leave out the integrator pole rather than cancel it
    bi.resize(2);
    ai.resize(2);
    bi << 0.0, g.ki * Ts;
    ai << 1.0, -1.0;
  }
  Eigen::VectorXd bd = Eigen::VectorXd::Zero(1), ad = Eigen::VectorXd::Ones(1);
  if (g.kd != 0.0) {  // without D, leave out the filter pole rather than cancel it
    const double den0 = 2.0 * g.tf_s + Ts;
    bd.resize(2);
    ad.resize(2);
    bd << 2.0 * g.kd / den0, -2.0 * g.kd / den0;
    ad << 1.0, (Ts - 2.0 * g.tf_s) / den0;
  }
  const Eigen::VectorXd den = conv(ai, ad);
  Eigen::VectorXd num = g.kp * den;
  num.head(bi.size() + ad.size() - 1) += conv(bi, ad);
  num.head(bd.size() + ai.size() - 1) += conv(bd, ai);
  return {num, den};
}

Pid::Pid(const PidGains& gains, double Ts, double tracking_time_s)
    : Ts_(Ts), fixed_tracking_time_(tracking_time_s) {
  set_gains(gains);
}

void Pid::set_gains(const PidGains& g) noexcept {
  g_ = g;
  const double den0 = 2.0 * g.tf_s + Ts_;
  a_d_ = (2.0 * g.tf_s - Ts_) / den0;
  b_d_ = 2.0 / den0;
  double tt = fixed_tracking_time_;
  if (tt <= 0.0) {
    const double ti = g.ki > 0.0 ? g.kp / g.ki : 0.0;
    const double td = g.kp > 0.0 ? g.kd / g.kp : 0.0;
    tt = (ti > 0.0 && td > 0.0) ? std::sqrt(ti * td) : ti;
  }
  // Tt below one sample would over-correct in a single step.
  tracking_gain_ = tt > 0.0 ? Ts_ / std::max(tt, Ts_) : 0.0;
}

double Pid::output(double e) noexcept {
  dfilt_now_ = a_d_ * dfilt_ + b_d_ * (e - e_prev_);
  return g_.kp * e + integral_ + g_.kd * dfilt_now_;
}

void Pid::commit(double e, double unclamped, double applied) noexcept {
  integral_ += g_.ki * Ts_ * e + tracking_gain_ * (applied - unclamped);
  dfilt_ = dfilt_now_;
  e_prev_ = e;
}

void Pid::align(double e, double target) noexcept {
  const double now = a_d_ * dfilt_ + b_d_ * (e - e_prev_);
  integral_ = target - g_.kp * e - g_.kd * now;
}

void Pid::reset() noexcept { integral_ = e_prev_ = dfilt_ = dfilt_now_ = 0.0; }

}  // namespace pvcgel::control
