#include "control/identification/sine_experiment.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "control/lti_filter.hpp"

namespace pvcgel::control::identification {

SineRecord run_sine_experiment(SimulatedRig& rig, const SinePoint& p) {
  SineRecord r;
  r.point = p;
  const double Ts = rig.config().sample_time_s;
  r.sample_time_s = Ts;
  // Round up (plus one sample) so the last analysed period is complete.
  const auto n = static_cast<size_t>(std::ceil(p.duration_s() / Ts - 1e-9)) + 1;
  r.t_s.resize(n);
  r.u_V.resize(n);
  r.y_um.resize(n);
  r.y_true_um.resize(n);
  rig.reset_steady_state(p.bias_V);
  for (size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * Ts;
    r.t_s[k] = t;
    r.y_true_um[k] = rig.true_displacement_um();
    r.y_um[k] = rig.measure();
    r.u_V[k] = p.voltage_V(t);
    rig.apply(r.u_V[k]);
  }
  return r;
}

std::vector<double> simulate_hammerstein(const HammersteinModel& m, const std::vector<double>& u, double Ts,
                                         int delay) {
  std::vector<double> y(u.size());
  if (u.empty()) return y;
  LtiFilter G(discretize_zoh(realize(m.G), Ts));
  G.reset_steady_state(m.f(u[0]));
  // y[k] is measured before u[k] acts: the filter output for this sample uses the
  // input from `delay` samples ago (held at u[0] before the record starts).
  for (size_t k = 0; k < u.size(); ++k) {
    const size_t j = k >= static_cast<size_t>(delay) ? k - static_cast<size_t>(delay) : 0;
    const double w = m.f(u[j]);
    y[k] = G.peek(w);
    G.step(w);
  }
  return y;
}

PredictionMetrics prediction_metrics(const std::vector<double>& y, const std::vector<double>& yh, size_t begin,
                                     size_t end) {
  if (y.size() != yh.size() || end > y.size() || begin >= end)
    throw std::invalid_argument("prediction_metrics: mismatched sizes or empty range");
  const double n = static_cast<double>(end - begin);
  double mean = 0.0, mean_e = 0.0;
  for (size_t k = begin; k < end; ++k) {
    mean += y[k];
    mean_e += y[k] - yh[k];
  }
  mean /= n;
  mean_e /= n;
  double ss = 0.0, se = 0.0, mx = 0.0;
  for (size_t k = begin; k < end; ++k) {
    ss += (y[k] - mean) * (y[k] - mean);
    const double e = y[k] - yh[k];
    se += e * e;
    mx = std::max(mx, std::abs(e));
  }
  PredictionMetrics m;
  m.rms_error_um = std::sqrt(se / n);
  m.nrmse = ss > 0.0 ? std::sqrt(se / ss) : INFINITY;
  m.max_error_um = mx;
  m.mean_error_um = mean_e;
  return m;
}

}  // namespace pvcgel::control::identification
