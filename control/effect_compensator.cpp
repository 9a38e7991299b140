#include "control/effect_compensator.hpp"
#include "control/text_format.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {
/// Largest slope of the saturation inverse at the stroke voltage_max_V reaches.
constexpr double kMaxSaturationInverseGain = 4.0;
/// Measurements closer to the saturation's ceiling (knee + softness) than this
/// share of the softness are read as this far: its inverse is unbounded there.
constexpr double kSaturationCeilingShare = 0.95;

}  // namespace

HysteresisOperator::HysteresisOperator(double alpha, double R, double spread) noexcept
    : r_(play_thresholds(R, spread)), a0_(1.0 - alpha), a_(alpha / kN) {
  for (size_t i = 0; i < kN; ++i) {
    prefix_[i] = a0_ + static_cast<double>(i) * a_;  // A_{i-1}
    b_[i] = -a_ / ((prefix_[i] + a_) * prefix_[i]);
    double s = a0_ * r_[i];
    for (size_t j = 0; j < i; ++j) s += a_ * (r_[i] - r_[j]);
    s_[i] = s;
  }
}

double HysteresisOperator::forward(double x) const noexcept {
  double h = a0_ * x;
  for (size_t i = 0; i < kN; ++i) h += a_ * std::clamp(plays_[i], x - r_[i], x + r_[i]);
  return h;
}

double HysteresisOperator::inverse(double h) const noexcept {
  double x = h / a0_, suffix = 0.0;
  for (size_t k = kN; k-- > 0;) {
    suffix += a_ * plays_[k];
    const double q = prefix_[k] * plays_[k] + suffix;  // the inverse play's state
    x += b_[k] * std::clamp(q, h - s_[k], h + s_[k]);
  }
  return x;
}

void HysteresisOperator::commit(double x) noexcept {
  for (size_t i = 0; i < kN; ++i) plays_[i] = std::clamp(plays_[i], x - r_[i], x + r_[i]);
}

EffectCompensator::EffectCompensator(const HammersteinModel& model, std::span<const Effect> effects, double Ts,
                                     double voltage_min_V, double voltage_max_V, int io_delay_samples,
                                     double operating_point_um)
    : Ts_(Ts) {
  // A model file holds at most kMaxEffects (read_effect_tables); more may be given here
  // (the benchmark runs every compensator at once), but no kind twice.
  for (const auto& e : effects) {
    if (e.kind == EffectKind::none) continue;
    const std::string k = "model.effect[" + std::to_string(count_) + "]";
    if (has(e.kind)) throw ConfigError(k, "effect '" + std::string(to_string(e.kind)) + "' given twice");
    validate(e, Ts, k);
    index_[static_cast<size_t>(e.kind)] = count_;
    p_[static_cast<size_t>(e.kind)] = e.p;
    effects_[static_cast<size_t>(count_++)] = e;
  }
  refuse_unsafe(voltage_max_V, operating_point_um);
  if (has(EffectKind::hysteresis)) hysteresis_ = HysteresisOperator(p(EffectKind::hysteresis)[0], p(EffectKind::hysteresis)[1],
                                                                p(EffectKind::hysteresis)[2]);
  if (has(EffectKind::slew_limit)) slew_step_V_ = p(EffectKind::slew_limit)[0] * Ts;
  if (has(EffectKind::saturation) && p(EffectKind::saturation)[2] != 0.0) drive_dc_gain_ = model.G.dc_gain();
  if (has(EffectKind::delay)) {
    const double d = p(EffectKind::delay)[0] / Ts;
    delay_whole_ = static_cast<int>(std::floor(d + 1e-9));
    delay_fraction_ = std::max(d - delay_whole_, 0.0);
    if (delay_fraction_ < 1e-9) delay_fraction_ = 0.0;
  }
  if (has(EffectKind::creep)) {
    for (const auto& [fraction, tau] : creep_branches(p(EffectKind::creep))) {
      const auto i = static_cast<size_t>(creep_branches_++);
      creep_a_[i] = std::exp(-Ts / tau);  // exact ZOH of fraction G(0) / (tau s + 1)
      creep_g_[i] = fraction * model.G.dc_gain();
      creep_fraction_ += fraction;
    }
    // The ZOH's own sample plus the I/O delay plus a delay effect's whole samples.
    creep_delay_ = std::clamp(io_delay_samples + delay_whole_, 0, kHistory - 2);
  }
  reset_steady_state(std::clamp(0.0, voltage_min_V, voltage_max_V));
}

void EffectCompensator::refuse_unsafe(double voltage_max_V, double operating_point_um) const {
  for (auto kind : {EffectKind::asymmetric_dynamics, EffectKind::bias_dependent_dynamics})
    if (has(kind))
      throw ConfigError(key(kind), std::string(to_string(kind)) +
                                       " cannot be compensated: its inverse is a G^-1 whose time scale depends on the "
                                       "state, which this controller does not run; remove the table (the disturbance "
                                       "observer then rejects it as a disturbance)");
  if (has(EffectKind::hysteresis) && p(EffectKind::hysteresis)[0] >= kMaxCompensatedHysteresisAlpha)
    throw ConfigError(key(EffectKind::hysteresis) + ".alpha",
                      format("alpha = %.3g: the inverse's slope after a reversal, 1 / (1 - alpha) = %.3g, is above "
                             "%.0f; it would turn sensor noise into voltage steps. Refit, or remove the table",
                             p(EffectKind::hysteresis)[0], 1.0 / (1.0 - p(EffectKind::hysteresis)[0]),
                             1.0 / (1.0 - kMaxCompensatedHysteresisAlpha)));
  if (has(EffectKind::dead_zone)) {
    const auto& q = p(EffectKind::dead_zone);
    if (q[0] + q[1] >= voltage_max_V)
      throw ConfigError(key(EffectKind::dead_zone),
                        format("threshold_V + catch_up_V = %.4g V is not below controller.voltage_max_V = %.4g V: "
                               "the dead zone's inverse needs voltages the limits forbid",
                               q[0] + q[1], voltage_max_V));
  }
  if (has(EffectKind::saturation)) {
    const auto& q = p(EffectKind::saturation);
    const double gain = 1.0 / soft_saturation_slope(operating_point_um, q);  // the inverse's slope there
    if (gain > kMaxSaturationInverseGain)
      throw ConfigError(key(EffectKind::saturation),
                        format("controller.operating_point_um = %.4g um lies deep beyond the knee (%.4g um from "
                               "centre_um = %.4g um): the inverse's slope there is %.3g (at most 4 is safe: it "
                               "multiplies sensor noise); refit, or move the operating point toward the centre",
                               operating_point_um, q[0], q[3], gain));
  }
}

std::string EffectCompensator::key(EffectKind kind) const {
  return "model.effect[" + std::to_string(index_[static_cast<size_t>(kind)]) + "]";
}

TransferFunction EffectCompensator::linear_model(const TransferFunction& G) const {
  if (!has(EffectKind::resonance)) return G;
  return linear_block(G, std::span<const Effect>(&effects_[static_cast<size_t>(index_[static_cast<size_t>(EffectKind::resonance)])], 1));
}

double EffectCompensator::slew_forward(double u) const noexcept {
  return has(EffectKind::slew_limit) ? slew_state_V_ + slew_mean_offset(u - slew_state_V_, slew_step_V_, slew_digital()) : u;
}

double EffectCompensator::slew_inverse(double x) const noexcept {
  if (!has(EffectKind::slew_limit)) return x;
  // The held step is its own inverse within reach; beyond it, the full step.
  if (slew_digital()) return slew_forward(x);
  // Mean of the ramp g = e - e|e| / (2 cap) for |e| <= cap: solved for e; beyond reach, the full step.
  const double cap = slew_step_V_, g = std::clamp(x - slew_state_V_, -0.5 * cap, 0.5 * cap);
  const double e = std::copysign(cap * (1.0 - std::sqrt(std::max(1.0 - 2.0 * std::abs(g) / cap, 0.0))), g);
  return slew_state_V_ + e;
}

double EffectCompensator::effective_input(double u) const noexcept {
  double x = slew_forward(u);
  if (has(EffectKind::dead_zone)) x = dead_zone(x, p(EffectKind::dead_zone)[0], p(EffectKind::dead_zone)[1]);
  return has(EffectKind::hysteresis) ? hysteresis_.forward(x) : x;
}

double EffectCompensator::rest_voltage_for(double x) const noexcept {
  if (!has(EffectKind::dead_zone) || x == 0.0) return x;
  // Inverse of the catch-up ramp; beyond it the dead zone passes u unchanged.
  const double d = p(EffectKind::dead_zone)[0], w = p(EffectKind::dead_zone)[1], a = std::abs(x);
  return a >= d + w ? x : std::copysign(d + a * w / (d + w), x);
}

double EffectCompensator::voltage_for(double x) const noexcept {
  const double before_hysteresis = has(EffectKind::hysteresis) ? hysteresis_.inverse(x) : x;
  return slew_inverse(rest_voltage_for(before_hysteresis));
}

void EffectCompensator::commit(double u, double w) noexcept {
  const double x = slew_forward(u);
  if (has(EffectKind::slew_limit)) slew_state_V_ += slew_state_step(u - slew_state_V_, slew_step_V_);
  if (has(EffectKind::hysteresis))
    hysteresis_.commit(has(EffectKind::dead_zone) ? dead_zone(x, p(EffectKind::dead_zone)[0], p(EffectKind::dead_zone)[1])
                                                  : x);
  if (creep_branches_ > 0) {
    w_history_[static_cast<size_t>(w_head_)] = w;
    const double w_in = w_history_[static_cast<size_t>((w_head_ - creep_delay_ + kHistory) % kHistory)];
    w_head_ = (w_head_ + 1) % kHistory;
    for (size_t i = 0; i < static_cast<size_t>(creep_branches_); ++i)
      creep_x_[i] = creep_a_[i] * creep_x_[i] + (1.0 - creep_a_[i]) * creep_g_[i] * w_in;
  }
  ++sample_;
}

void EffectCompensator::reset_steady_state(double u) noexcept {
  slew_state_V_ = u;
  hysteresis_.reset(has(EffectKind::dead_zone) ? dead_zone(u, p(EffectKind::dead_zone)[0], p(EffectKind::dead_zone)[1]) : u);
  sample_ = 0;
}

void EffectCompensator::reset_creep(double w) noexcept {
  w_history_.fill(w);
  w_head_ = 0;
  for (size_t i = 0; i < static_cast<size_t>(creep_branches_); ++i) creep_x_[i] = creep_g_[i] * w;
}

double EffectCompensator::creep_ahead(int ahead) const noexcept {
  double total = 0.0;
  for (size_t i = 0; i < static_cast<size_t>(creep_branches_); ++i) {
    double x = creep_x_[i];
    // Inputs already applied reach the branch creep_delay_ samples later; beyond them the last one is held.
    for (int j = 0; j < ahead; ++j) {
      const int back = std::max(creep_delay_ - j, 1);
      x = creep_a_[i] * x + (1.0 - creep_a_[i]) * creep_g_[i] *
                                w_history_[static_cast<size_t>((w_head_ - back + kHistory) % kHistory)];
    }
    total += x;
  }
  return total;
}

double EffectCompensator::saturation_inverse(double y) const noexcept {
  if (!has(EffectKind::saturation)) return y;
  const double knee = p(EffectKind::saturation)[0], Y = p(EffectKind::saturation)[1], centre = p(EffectKind::saturation)[3];
  const double out = std::min(std::abs(y - centre) - knee, kSaturationCeilingShare * Y);
  if (out <= 0.0) return y;
  // out = e / sqrt(1 + (e / Y)^2) solved for e.
  return centre + std::copysign(knee + out / std::sqrt(1.0 - (out / Y) * (out / Y)), y - centre);
}

double EffectCompensator::drive(double w) const noexcept {
  return drive_dc_gain_ == 0.0 ? w : saturated_drive(w, drive_dc_gain_, p(EffectKind::saturation));
}

double EffectCompensator::drive_slope(double w) const noexcept {
  if (drive_dc_gain_ == 0.0) return 1.0;
  const auto& q = p(EffectKind::saturation);
  return soft_saturation_slope(drive_dc_gain_ * w, q);
}

double EffectCompensator::drive_inverse(double w) const noexcept {
  return drive_dc_gain_ == 0.0 ? w : saturation_inverse(drive_dc_gain_ * w) / drive_dc_gain_;
}

double EffectCompensator::output_side_inverse(double y, double ahead) const noexcept {
  if (has(EffectKind::drift)) y -= drift_um(p(EffectKind::drift), (static_cast<double>(sample_) + ahead) * Ts_);
  return drive_dc_gain_ == 0.0 ? saturation_inverse(y) : y;
}

double EffectCompensator::linear_output(double y, double ahead) const noexcept {
  const double y_total = output_side_inverse(y, ahead);
  return creep_branches_ > 0 ? y_total - creep_ahead(static_cast<int>(ahead)) : y_total;
}

}  // namespace pvcgel::control
