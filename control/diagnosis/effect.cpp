#include "control/diagnosis/effect.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "control/config_error.hpp"
#include "control/state_space.hpp"

namespace pvcgel::control::diagnosis {

namespace {

constexpr std::array<std::string_view, 11> kNames{"none",  "hysteresis", "creep",     "dead_zone",
                                                  "saturation", "delay", "asymmetric_dynamics", "slew_limit",
                                                  "resonance",  "drift", "bias_dependent_dynamics"};

/// Play thresholds at the quantiles of an exponential distribution (mean 1):
/// the lag after a reversal grows linearly, then saturates exponentially.
constexpr std::array<double, 8> kPlayQuantiles{0.0645, 0.2076, 0.3677, 0.5596, 0.7985, 1.0986, 1.5041, 2.0794};

std::vector<double> add_polynomials(std::vector<double> a, std::vector<double> b) {
  if (a.size() < b.size()) std::swap(a, b);
  const size_t off = a.size() - b.size();
  for (size_t i = 0; i < b.size(); ++i) a[off + i] += b[i];
  return a;
}

/// The linear block with the effect's LTI part folded in (creep branch in
/// parallel, structural mode in series), so one exact ZOH covers it.
TransferFunction linear_block(const TransferFunction& G, const Effect& e) {
  if (e.kind == EffectKind::creep) {
    const std::vector<double> branch_den{e.p[1], 1.0};
    auto num = add_polynomials(polynomial_multiply(G.num(), branch_den),
                               polynomial_multiply({e.p[0] * G.dc_gain()}, G.den()));
    return TransferFunction(num, polynomial_multiply(G.den(), branch_den));
  }
  if (e.kind == EffectKind::resonance) {
    const double wn = 2.0 * std::numbers::pi * e.p[0];
    return TransferFunction(polynomial_multiply(G.num(), {wn * wn}),
                            polynomial_multiply(G.den(), {1.0, 2.0 * e.p[1] * wn, wn * wn}));
  }
  return G;
}

/// No response up to d, linear catch-up to u over the next w volts, then u.
double dead_zone(double u, double d, double w) noexcept {
  const double a = std::abs(u);
  return std::copysign(a <= d ? 0.0 : (a <= d + w ? (a - d) * (d + w) / w : a), u);
}

}  // namespace

std::string_view to_string(EffectKind kind) noexcept { return kNames[static_cast<size_t>(kind)]; }

std::optional<EffectKind> parse_effect_kind(std::string_view name) noexcept {
  for (size_t i = 0; i < kNames.size(); ++i)
    if (kNames[i] == name) return static_cast<EffectKind>(i);
  return std::nullopt;
}

std::vector<ParameterSpec> parameter_specs(EffectKind kind, double Ts, double duration_s) {
  switch (kind) {
    case EffectKind::none: return {};
    case EffectKind::hysteresis:
      return {{"alpha", 0.0, 1.0, false, {0.005, 0.02, 0.06}}, {"threshold_scale_V", 0.5, 500.0, true, {3, 10, 30, 100}}};
    case EffectKind::creep:
      return {{"fraction", -0.3, 0.3, false, {0.003, -0.003}}, {"time_constant_s", 0.1, 300.0, true, {0.5, 2, 8, 30}}};
    case EffectKind::dead_zone:
      return {{"threshold_V", 0.0, 400.0, false, {3, 10, 30, 80, 150}}, {"catch_up_V", 0.5, 400.0, true, {5, 30, 100}}};
    case EffectKind::saturation:
      return {{"knee_um", 0.0, 5000.0, false, {0, 100, 250}}, {"softness_um", 20.0, 1e6, true, {300, 1000, 4000}}};
    case EffectKind::delay: {
      const double n_max = static_cast<double>(kDelayLineSamples - 20);
      return {{"extra_delay_s", 0.0, n_max * Ts, false, {0.5 * Ts, 1 * Ts, 2 * Ts, 4 * Ts, 8 * Ts, 16 * Ts}}};
    }
    case EffectKind::asymmetric_dynamics:
      return {{"relaxation_slowdown", -0.7, 2.5, false, {-0.2, 0.2, 0.6}}};
    case EffectKind::slew_limit:
      return {{"slew_rate_V_per_s", 1.0, 1e7, true, {100, 200, 400, 800, 1600, 3200, 6400, 12800, 25600, 51200}}};
    case EffectKind::resonance: {
      const double f_max = 0.4 / Ts;
      std::vector<double> starts;
      for (double f : {3.0, 8.0, 16.0, 32.0, 64.0})
        if (f < f_max) starts.push_back(f);
      return {{"frequency_Hz", 0.5, f_max, true, starts}, {"damping_ratio", 0.005, 2.0, true, {0.05, 0.3}}};
    }
    case EffectKind::drift:
      return {{"offset_um", -100.0, 100.0, false, {0.0}},
              {"rate_um_per_s", -20.0, 20.0, false, {-0.01, 0.01}},
              {"onset_s", 0.0, std::max(duration_s, 0.0), false, {0.0, 0.25 * duration_s, 0.5 * duration_s}}};
    case EffectKind::bias_dependent_dynamics:
      return {{"beta", -0.7, 3.0, false, {-0.2, 0.2, 0.6}}, {"operating_point_time_constant_s", 0.0, 20.0, false, {0.0, 0.5, 3.0}}};
  }
  return {};
}

std::string_view physical_meaning(EffectKind kind) noexcept {
  switch (kind) {
    case EffectKind::none: return "the nominal model explains the data to within the sensor noise";
    case EffectKind::hysteresis:
      return "rate-independent hysteresis: the effective voltage lags the applied voltage after each reversal "
             "(Prandtl-Ishlinskii play operators), so rising and falling branches differ";
    case EffectKind::creep:
      return "viscoelastic creep: a slow relaxation branch keeps the displacement moving after the fast "
             "dynamics have settled";
    case EffectKind::dead_zone:
      return "activation threshold: below a threshold voltage the gel does not respond";
    case EffectKind::saturation:
      return "stroke limit: the displacement softens above a knee instead of following the model";
    case EffectKind::delay: return "extra transport / I/O delay between the command and the motion";
    case EffectKind::asymmetric_dynamics:
      return "asymmetric dynamics: relaxation (displacement falling toward its target) runs at a different "
             "speed than contraction";
    case EffectKind::slew_limit:
      return "slew limit: the amplifier cannot charge the actuator's capacitance faster than a fixed rate";
    case EffectKind::resonance: return "a structural resonance (mass-spring mode) in series with the gel dynamics";
    case EffectKind::drift:
      return "input-independent drift (thermal or sensor): a slow offset that does not depend on the voltage";
    case EffectKind::bias_dependent_dynamics:
      return "operating-point-dependent dynamics: the poles move (slow down or speed up) with the displacement";
  }
  return "";
}

void validate(const Effect& e, double Ts, const std::string& key) {
  const auto specs = parameter_specs(e.kind, Ts, 1e300);
  for (size_t i = 0; i < specs.size(); ++i) {
    const auto& s = specs[i];
    if (!std::isfinite(e.p[i]) || e.p[i] < s.lower || e.p[i] > s.upper)
      throw ConfigError(key + "." + s.name, "must be in [" + std::to_string(s.lower) + ", " +
                                                std::to_string(s.upper) + "], got " + std::to_string(e.p[i]));
  }
}

AugmentedPlant::AugmentedPlant(const HammersteinModel& model, int io_delay, double Ts, const Effect& e)
    : e_(e), f_(model.f), Ts_(Ts), io_delay_(io_delay) {
  if (!(Ts > 0.0)) throw ConfigError("sample_time_s", "must be positive");
  if (io_delay < 0 || io_delay > 8) throw ConfigError("model.io_delay_samples", "must be 0..8 samples");
  if (!model.G.is_stable()) throw ConfigError("model.G", "G(s) = " + model.G.to_string() + " is unstable");
  validate(e, Ts, "effect");
  if (const auto turn = f_.first_turnover(1000.0)) x_sat_ = *turn;
  const auto ss = realize(linear_block(model.G, e), "model.G");
  if (ss.order() > kMaxOrder) throw ConfigError("model.G", "order above " + std::to_string(kMaxOrder));
  if (e.kind == EffectKind::asymmetric_dynamics) {
    scale_grid_ = {1.0, 1.0 + e.p[0]};
  } else if (e.kind == EffectKind::bias_dependent_dynamics) {
    for (int i = 0; i <= 40; ++i) scale_grid_.push_back(std::exp(std::log(4.0) * (i - 20) / 20.0));
    scale_grid_[20] = 1.0;
  } else {
    scale_grid_ = {1.0};
  }
  for (double s : scale_grid_) {
    StateSpace scaled = ss;
    scaled.A /= s;
    scaled.B /= s;
    const auto d = discretize_zoh(scaled, Ts);
    A_grid_.emplace_back(d.A);
    B_grid_.emplace_back(d.B);
    C_ = d.C;
    D_ = d.D;
  }
  dc_gain_ = model.G.dc_gain();
  if (e.kind == EffectKind::bias_dependent_dynamics) op_gain_ = e.p[1] > 0.0 ? 1.0 - std::exp(-Ts / e.p[1]) : 1.0;
  y_ref_ = std::max(std::abs(dc_gain_ * nonlinearity(500.0)), 1e-6);
  x_ = Vector::Zero(ss.order());
  reset_steady_state(0.0);
}

double AugmentedPlant::time_scale(double w) const noexcept {
  if (e_.kind == EffectKind::asymmetric_dynamics) return dc_gain_ * w < y_lin_ ? 1.0 : 0.0;  // grid index
  return std::clamp(1.0 + e_.p[0] * y_op_ / y_ref_, 0.25, 4.0);
}

double AugmentedPlant::output_stage(double y, long sample) const noexcept {
  if (e_.kind == EffectKind::saturation) {
    const double excess = y - e_.p[0];
    if (excess > 0.0) y = e_.p[0] + excess / std::sqrt(1.0 + (excess / e_.p[1]) * (excess / e_.p[1]));
  } else if (e_.kind == EffectKind::drift) {
    y += e_.p[0] + e_.p[1] * std::max(static_cast<double>(sample) * Ts_ - e_.p[2], 0.0);
  }
  return y;
}

void AugmentedPlant::reset_steady_state(double u) noexcept {
  delay_line_.fill(u);
  head_ = 0;
  slew_state_ = u;
  sample_ = 0;
  // u once through the static input stage, play operators virgin.
  double x = u;
  if (e_.kind == EffectKind::dead_zone) x = dead_zone(u, e_.p[0], e_.p[1]);
  plays_.fill(x);
  const double w = nonlinearity(x);
  const size_t unit = e_.kind == EffectKind::bias_dependent_dynamics ? 20 : 0;
  const Matrix I = Matrix::Identity(A_grid_[unit].rows(), A_grid_[unit].cols());
  x_ = (I - A_grid_[unit]).partialPivLu().solve(B_grid_[unit] * w);
  y_lin_ = y_op_ = C_.dot(x_) + D_ * w;
  y_ = output_stage(y_lin_, 0);
}

void AugmentedPlant::apply(double u) noexcept {
  delay_line_[static_cast<size_t>(head_)] = u;
  double delay = io_delay_;
  if (e_.kind == EffectKind::delay) delay += e_.p[0] / Ts_;
  const int whole = static_cast<int>(delay);
  const double frac = delay - whole;
  const auto at = [&](int back) { return delay_line_[static_cast<size_t>((head_ - back + 2 * kDelayLine) % kDelayLine)]; };
  double x = frac > 0.0 ? (1.0 - frac) * at(whole) + frac * at(whole + 1) : at(whole);
  head_ = (head_ + 1) % kDelayLine;

  switch (e_.kind) {
    case EffectKind::slew_limit: {
      // The amplifier ramps at the slew rate inside the sample: hold its mean over the sample.
      const double cap = e_.p[0] * Ts_, e = x - slew_state_;
      if (std::abs(e) <= cap) {
        x -= 0.5 * e * std::abs(e) / cap;
        slew_state_ += e;
      } else {
        x = slew_state_ + std::copysign(0.5 * cap, e);
        slew_state_ += std::copysign(cap, e);
      }
      break;
    }
    case EffectKind::dead_zone: x = dead_zone(x, e_.p[0], e_.p[1]); break;
    case EffectKind::hysteresis: {
      double lag = 0.0;
      for (int i = 0; i < kPlays; ++i) {
        const double r = e_.p[1] * kPlayQuantiles[static_cast<size_t>(i)];
        auto& p = plays_[static_cast<size_t>(i)];
        p = std::clamp(p, x - r, x + r);
        lag += x - p;
      }
      x -= e_.p[0] * lag / kPlays;
      break;
    }
    default: break;
  }
  const double w = nonlinearity(x);
  if (scale_grid_.size() == 1) {
    x_ = A_grid_[0] * x_ + B_grid_[0] * w;
  } else if (e_.kind == EffectKind::asymmetric_dynamics) {
    const auto i = static_cast<size_t>(time_scale(w));
    x_ = A_grid_[i] * x_ + B_grid_[i] * w;
  } else {
    // Interpolate between the two neighbouring discretisations (log-spaced grid).
    const double s = time_scale(w);
    const double pos = std::clamp(20.0 + 20.0 * std::log(s) / std::log(4.0), 0.0, 39.999);
    const auto i = static_cast<size_t>(pos);
    const double t = pos - static_cast<double>(i);
    Vector next = (1.0 - t) * (A_grid_[i] * x_ + B_grid_[i] * w);
    next += t * (A_grid_[i + 1] * x_ + B_grid_[i + 1] * w);
    x_ = next;
  }
  y_lin_ = C_.dot(x_) + D_ * w;
  y_op_ += op_gain_ * (y_lin_ - y_op_);
  ++sample_;
  y_ = output_stage(y_lin_, sample_);
}

double AugmentedPlant::rest_voltage(double y, double lo, double hi) noexcept {
  reset_steady_state(lo);
  const bool increasing_lo = output() < y;
  for (int i = 0; i < 60 && hi - lo > 1e-9; ++i) {
    const double mid = 0.5 * (lo + hi);
    reset_steady_state(mid);
    (output() < y) == increasing_lo ? lo = mid : hi = mid;
  }
  const double v = 0.5 * (lo + hi);
  reset_steady_state(v);
  return v;
}

std::vector<double> AugmentedPlant::simulate(const std::vector<double>& u, double initial_V) {
  std::vector<double> y(u.size());
  if (u.empty()) return y;
  reset_steady_state(initial_V);
  for (size_t k = 0; k < u.size(); ++k) {
    y[k] = y_;
    apply(u[k]);
  }
  return y;
}

}  // namespace pvcgel::control::diagnosis
