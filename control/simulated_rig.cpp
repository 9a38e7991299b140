#include "control/simulated_rig.hpp"

#include <cmath>

#include "control/config_error.hpp"
#include "control/text_format.hpp"

namespace pvcgel::control {

SimulatedRig::SimulatedRig(const SimRigConfig& c) : cfg_(c), rng_(c.seed) {
  if (!(c.sample_time_s > 0.0)) throw ConfigError("sim.sample_time_s", "must be positive");
  if (c.io_delay_samples < 0 || c.io_delay_samples >= kMaxDelay)
    throw ConfigError("sim.io_delay_samples", "must be 0.." + std::to_string(kMaxDelay - 1));
  if (!(c.noise_sigma_um >= 0.0)) throw ConfigError("sim.noise_sigma_um", "must be >= 0");
  if (!(c.quantization_um >= 0.0)) throw ConfigError("sim.quantization_um", "must be >= 0");
  if (c.hysteresis.enabled && !(c.hysteresis.saturation_V > 0.0 && c.hysteresis.alpha >= 0.0))
    throw ConfigError("sim.hysteresis", "saturation_V must be > 0 and alpha >= 0");
  if (c.creep.enabled && !(c.creep.time_constant_s > 0.0 && c.creep.fraction >= 0.0))
    throw ConfigError("sim.creep", "time_constant_s must be > 0 and fraction >= 0");
  if (!c.truth.G.is_stable()) throw ConfigError("sim.truth.G", "truth G(s) must be stable");
  G_ = LtiFilter(discretize_zoh(realize(c.truth.G, "sim.truth.G"), c.sample_time_s));
  const TransferFunction creep({c.creep.fraction * c.truth.G.dc_gain()}, {c.creep.time_constant_s, 1.0});
  creep_ = LtiFilter(discretize_zoh(realize(creep), c.sample_time_s));
  if (const auto turn = c.truth.f.first_turnover(1000.0)) x_sat_ = *turn;
  if (!c.added_effects.empty()) {
    if (c.hysteresis.enabled || c.creep.enabled)
      throw ConfigError("sim.truth.effect", "a diagnosed effect replaces the rig's built-in effects: set [sim.hysteresis] "
                                            "and [sim.creep] enabled = false");
    augmented_.emplace(c.truth, c.io_delay_samples, c.sample_time_s, std::span<const Effect>(c.added_effects));
    if (const double modulus = augmented_->largest_discrete_pole_modulus(); !(modulus < 1.0))
      throw ConfigError("sim.truth.effect", format("the model with these effects discretises to an unstable block at "
                                                   "%.6g s (largest pole modulus %.6g; a stable block maps below 1)",
                                                   c.sample_time_s, modulus));
    for (const auto& e : c.added_effects)
      if (e.kind == EffectKind::drift) wander_step_um_ = e.p[kDriftWander] * std::sqrt(c.sample_time_s);
  }
  reset_steady_state(0.0);
}

double SimulatedRig::static_output(double x) const noexcept { return cfg_.truth.f(std::min(x, x_sat_)); }

void SimulatedRig::reset_steady_state(double u) noexcept {
  if (augmented_) {
    augmented_->reset_steady_state(u);
    wander_um_ = 0.0;
    y_true_ = augmented_->output();
    return;
  }
  delay_line_.fill(u);
  u_prev_ = u;
  h_ = 0.0;
  const double w = static_output(u);
  G_.reset_steady_state(w);
  creep_.reset_steady_state(w);
  y_true_ = G_.peek(w) + (cfg_.creep.enabled ? creep_.peek(w) : 0.0);
}

double SimulatedRig::measure() noexcept {
  double y = y_true_;
  if (cfg_.noise_sigma_um > 0.0) y += cfg_.noise_sigma_um * noise_(rng_);
  if (cfg_.quantization_um > 0.0) y = std::round(y / cfg_.quantization_um) * cfg_.quantization_um;
  return y;
}

void SimulatedRig::apply(double u) noexcept {
  if (augmented_) {
    augmented_->apply(u);
    if (wander_step_um_ > 0.0) wander_um_ += wander_step_um_ * noise_(rng_);
    y_true_ = augmented_->output() + wander_um_;
    return;
  }
  // The amplifier output during this sample is the command from io_delay samples ago.
  const int d = cfg_.io_delay_samples;
  delay_line_[static_cast<size_t>(delay_head_)] = u;
  const double u_eff = delay_line_[static_cast<size_t>((delay_head_ - d + kMaxDelay) % kMaxDelay)];
  delay_head_ = (delay_head_ + 1) % kMaxDelay;

  double x = u_eff;
  if (cfg_.hysteresis.enabled) {
    const double du = u_eff - u_prev_;
    const double k = 1.0 / (2.0 * cfg_.hysteresis.saturation_V);
    h_ += du - k * (std::abs(du) * h_ + du * std::abs(h_));
    x = u_eff - cfg_.hysteresis.alpha * h_;
  }
  u_prev_ = u_eff;
  const double w = static_output(x);
  // The state after this step gives the displacement at the start of the next cycle.
  G_.step(w);
  const double creep_now = cfg_.creep.enabled ? (creep_.step(w), creep_.peek(w)) : 0.0;
  y_true_ = G_.peek(w) + creep_now;
}

}  // namespace pvcgel::control
