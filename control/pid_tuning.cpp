#include "control/pid_tuning.hpp"
#include "control/text_format.hpp"

#include <cmath>
#include <limits>
#include <numbers>

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {
constexpr double kDeg = 180.0 / std::numbers::pi;

PidGains family(double kp, double Ti, const TuningTarget& t, double Ts) {
  const double Td = t.derivative_ratio * Ti;
  return {kp, kp / Ti, kp * Td, std::max(Td / t.derivative_filter_n, Ts)};
}

double wrap_deg(double a) {
  while (a > 180.0) a -= 360.0;
  while (a <= -180.0) a += 360.0;
  return a;
}
}  // namespace

Eigen::VectorXcd closed_loop_poles(const DiscreteTransferFunction& c, const DiscreteTransferFunction& p) {
  const auto ac = (c * p);  // b_C b_P and a_C a_P in one product
  Eigen::VectorXd chr = Eigen::VectorXd::Zero(std::max(ac.a.size(), ac.b.size()));
  chr.head(ac.a.size()) += ac.a;
  chr.head(ac.b.size()) += ac.b;
  return DiscreteTransferFunction{Eigen::VectorXd::Ones(1), chr}.poles();
}

LoopMargins loop_margins(const DiscreteTransferFunction& c, const DiscreteTransferFunction& p, double Ts) {
  LoopMargins m;
  m.gain_margin_db = std::numeric_limits<double>::infinity();
  const double w_lo = 1e-3, w_hi = std::numbers::pi / Ts * 0.999;
  const int n = 6000;
  double prev_mag = 0.0, prev_phase = 0.0, unwrapped = 0.0;
  bool have_crossover = false, have_gm = false;
  for (int i = 0; i <= n; ++i) {
    const double w = w_lo * std::pow(w_hi / w_lo, static_cast<double>(i) / n);
    const std::complex<double> L = c.frequency_response(w, Ts) * p.frequency_response(w, Ts);
    const double mag = std::abs(L);
    const double ph = std::arg(L) * kDeg;
    unwrapped = (i == 0) ? ph : unwrapped + wrap_deg(ph - prev_phase);
    if (i > 0 && !have_crossover && prev_mag >= 1.0 && mag < 1.0) {
      m.crossover_rad_s = w;
      m.phase_margin_deg = 180.0 + unwrapped;
      have_crossover = true;
    }
    if (i > 0 && !have_gm && unwrapped <= -180.0) {
      m.gain_margin_db = -20.0 * std::log10(mag);
      have_gm = true;
    }
    prev_mag = mag;
    prev_phase = ph;
  }
  m.max_closed_loop_pole_abs = closed_loop_poles(c, p).cwiseAbs().maxCoeff();
  return m;
}

TuningResult tune_pid(const DiscreteTransferFunction& plant, double Ts, const TuningTarget& t) {
  const double wc = t.crossover_rad_s;
  if (!(wc > 0.0 && wc < std::numbers::pi / Ts))
    throw ConfigError("controller.tuning.crossover_rad_s", format("must be in (0, Nyquist = %g) rad/s", std::numbers::pi / Ts));
  if (!(t.phase_margin_deg > 0.0 && t.phase_margin_deg < 90.0))
    throw ConfigError("controller.tuning.phase_margin_deg", "must be in (0, 90) degrees");
  const std::complex<double> P = plant.frequency_response(wc, Ts);
  const double need_deg = wrap_deg(-180.0 + t.phase_margin_deg - std::arg(P) * kDeg);
  auto ctrl_phase = [&](double Ti) {
    return std::arg(pid_transfer_function(family(1.0, Ti, t, Ts), Ts).frequency_response(wc, Ts)) * kDeg;
  };
  // The family's phase rises from -90 deg (pure integral) as Ti grows; find the first crossing.
  const double lo = 1e-4 / wc, hi = 1e4 / wc;
  const int n = 800;
  double Ti_a = lo, ph_a = ctrl_phase(lo) - need_deg;
  double max_phase = -90.0;
  bool found = false;
  double Ti_b = lo;
  for (int i = 1; i <= n; ++i) {
    Ti_b = lo * std::pow(hi / lo, static_cast<double>(i) / n);
    const double ph = ctrl_phase(Ti_b);
    max_phase = std::max(max_phase, ph);
    if ((ph - need_deg) * ph_a <= 0.0) {
      found = true;
      break;
    }
    Ti_a = Ti_b;
    ph_a = ph - need_deg;
  }
  if (!found) {
    throw ConfigError("controller.tuning",
                      format("no PID reaches %.0f deg phase margin at %.1f rad/s: the plant's phase there is %.1f deg, "
                             "so the controller must add %.1f deg, but this PID family spans -90..%.1f deg; lower the "
                             "crossover or the phase margin",
                             t.phase_margin_deg, wc, std::arg(P) * kDeg, need_deg, max_phase));
  }
  for (int it = 0; it < 80; ++it) {  // bisection on log Ti
    const double mid = std::sqrt(Ti_a * Ti_b);
    const double ph = ctrl_phase(mid) - need_deg;
    if (ph * ph_a <= 0.0) Ti_b = mid; else { Ti_a = mid; ph_a = ph; }
  }
  const double Ti = std::sqrt(Ti_a * Ti_b);
  const auto unit = pid_transfer_function(family(1.0, Ti, t, Ts), Ts);
  const double kp = 1.0 / std::abs(unit.frequency_response(wc, Ts) * P);
  TuningResult r;
  r.gains = family(kp, Ti, t, Ts);
  r.margins = loop_margins(pid_transfer_function(r.gains, Ts), plant, Ts);
  return r;
}

}  // namespace pvcgel::control
