#include "control/controller.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "control/config_error.hpp"
#include "control/text_format.hpp"

namespace pvcgel::control {

namespace {

void check_range(const std::string& key, double v, double lo, double hi) {
  if (!(std::isfinite(v) && v >= lo && v <= hi)) {
    std::ostringstream os;
    os << "value " << v << " is outside the allowed range [" << lo << ", " << hi << "]";
    throw ConfigError(key, os.str());
  }
}

void check_voltage_limits(const ControllerConfig& cfg) {
  check_range("controller.voltage_min_V", cfg.voltage_min_V, 0.0, 1000.0);
  check_range("controller.voltage_max_V", cfg.voltage_max_V, 0.0, 1000.0);
  if (!(cfg.voltage_max_V > cfg.voltage_min_V))
    throw ConfigError("controller.voltage_max_V", "must be above controller.voltage_min_V");
}

/// The effects' compensator, checked against what the loop can give: a delay is
/// compensated through the reference preview and the sampled model's delay (at most 8 samples).
EffectCompensator checked_compensator(const HammersteinModel& model, const ControllerConfig& cfg) {
  check_voltage_limits(cfg);
  EffectCompensator comp(model, cfg.effects, cfg.sample_time_s, cfg.voltage_min_V, cfg.voltage_max_V,
                         cfg.io_delay_samples, cfg.operating_point_um);
  const int delay = cfg.io_delay_samples + comp.extra_delay_samples();
  const int preview = 1 + delay + (comp.extra_delay_fraction() > 0.0 ? 1 : 0);
  if (comp.extra_delay_samples() > 0 && (preview > cfg.max_preview_samples || delay > 8))
    throw ConfigError(comp.key(EffectKind::delay),
                      "compensating this delay needs " + std::to_string(preview) +
                          " samples of reference preview (the loop gives " + std::to_string(cfg.max_preview_samples) +
                          ") and " + std::to_string(delay) + " samples of delay in the sampled model (at most 8)");
  return comp;
}

/// The effect that changes the sampled linear model (a resonance before a delay), if any.
std::optional<size_t> linear_effect(const std::vector<Effect>& effects) {
  for (auto kind : {EffectKind::resonance, EffectKind::delay})
    for (size_t i = 0; i < effects.size(); ++i)
      if (effects[i].kind == kind) return i;
  return std::nullopt;
}

void check_gains(const PidGains& g, ControllerMode m, double Ts) {
  const std::string key = "controller.pid." + std::string(to_string(m));
  const std::pair<const char*, double> fields[] = {{"kp", g.kp}, {"ki", g.ki}, {"kd", g.kd}, {"tf_s", g.tf_s}};
  for (const auto& [name, v] : fields)
    if (!std::isfinite(v) || v < 0.0)
      throw ConfigError(key + "." + name, "must be a finite, non-negative number");
  if (g.kd > 0.0 && g.tf_s < Ts)
    throw ConfigError(key + ".tf_s", "derivative filter time constant must be at least one sample");
}
}  // namespace

std::optional<ControllerMode> parse_mode(std::string_view name) noexcept {
  for (auto m : kAllModes)
    if (to_string(m) == name) return m;
  return std::nullopt;
}

Controller::Controller(const HammersteinModel& model, const ControllerConfig& cfg) try
    : cfg_(cfg),
      comp_(checked_compensator(model, cfg)),
      model_{model.f, comp_.linear_model(model.G)},
      plant_(DiscretePlantModel::make(model_.G, cfg.sample_time_s, cfg.io_delay_samples + comp_.extra_delay_samples())),
      inverse_([&] {
        // f must be monotone over the limits (this throws with the usable range if not);
        // the inverse itself spans as far as f stays monotone, so a request beyond the
        // limits shows up as an unclamped voltage the output stage then clamps.
        (void)PolynomialInverse(model.f, cfg.voltage_min_V, cfg.voltage_max_V);
        const auto turn = model.f.first_turnover(1000.0);
        const double upper = turn ? std::max(cfg.voltage_max_V, 0.999 * *turn) : 1000.0;
        return PolynomialInverse(model.f, 0.0, upper);
      }()),
      dob_(model_, plant_, cfg.dob_lambda_s, cfg.dob_q_order),
      ff_(plant_),
      // p acts on G's input, so its range is the drive the voltage limits reach.
      correction_(dob_, plant_, comp_.drive(model.f(cfg.voltage_min_V)), comp_.drive(model.f(cfg.voltage_max_V)),
                  cfg.learning_memory_s),
      mode_(cfg.mode),
      pending_mode_(cfg.mode) {
  check_range("controller.slew_limit_V_per_s", cfg.slew_limit_V_per_s, 0.0, 1e9);
  check_range("controller.antiwindup_tracking_time_s", cfg.antiwindup_tracking_time_s, 0.0, 1e3);
  check_range("controller.operating_point_um", cfg.operating_point_um, 0.0, 1e5);
  output_ = OutputStage(cfg.voltage_min_V, cfg.voltage_max_V, cfg.slew_limit_V_per_s, cfg.sample_time_s);

  const double dc = model_.G.dc_gain();
  // Mode pid has no inverse: a saturation on the drive lowers its plant's gain with f's slope.
  const double u_op =
      std::clamp(inverse_(comp_.drive_inverse(cfg.operating_point_um / dc)), cfg.voltage_min_V, cfg.voltage_max_V);
  pid_plant_gain_ = model_.f.derivative(u_op) * comp_.drive_slope(model_.f(u_op));
  if (!(pid_plant_gain_ > 0.0)) throw ConfigError("controller.operating_point_um", "f' is not positive there");
  tune_modes();
  pid_ = Pid(gains_[static_cast<size_t>(mode_)], cfg.sample_time_s, cfg.antiwindup_tracking_time_s);
  reset_steady_state(cfg.operating_point_um);
} catch (const ConfigError& e) {
  // A design check (minimum phase, proper Q G^-1, closed-loop stability) that holds for the
  // model alone but fails with an effect folded into G is that effect's fault: name it.
  const auto culprit = linear_effect(cfg.effects);
  if (!culprit || e.key().starts_with("model.effect")) throw;
  ControllerConfig plain = cfg;
  plain.effects.clear();
  (void)Controller(model, plain);  // throws the model's own error if the model alone fails
  throw ConfigError("model.effect[" + std::to_string(*culprit) + "]",
                    "cannot be compensated: with its " + std::string(to_string(cfg.effects[*culprit].kind)) +
                        " folded into the linear model, " + e.what());
}

void Controller::tune_modes() {
  const auto& cfg = cfg_;
  for (auto m : kAllModes) {
    const auto i = static_cast<size_t>(m);
    auto plant = design_plant(m);
    check_range("controller.tuning_gain_scale", cfg.tuning_gain_scale[i], 1e-3, 1e3);
    plant.b *= cfg.tuning_gain_scale[i];
    gains_[i] = cfg.tuning ? tune_pid(plant, cfg.sample_time_s, *cfg.tuning).gains : cfg.gains[i];
    check_gains(gains_[i], m, cfg.sample_time_s);
    margins_[i] = loop_margins(pid_transfer_function(gains_[i], cfg.sample_time_s), plant, cfg.sample_time_s);
    if (!margins_[i].stable()) {
      throw ConfigError("controller.pid." + std::string(to_string(m)),
                        format("closed loop of mode %s is unstable on the configured model (largest closed-loop pole "
                               "|z| = %.4f >= 1); reduce the gains",
                               to_string(m).data(), margins_[i].max_closed_loop_pole_abs));
    }
  }
}

DiscreteTransferFunction Controller::design_plant(ControllerMode m) const {
  auto p = plant_.G_d;
  // Mode pid drives the voltage, so it sees f linearised at the operating point;
  // the inverse modes see G alone (the inverse cancels f on the model).
  if (m == ControllerMode::pid) p.b *= pid_plant_gain_;
  return p;
}

double Controller::linear_input_for(double voltage_V, ControllerMode m) const noexcept {
  const double w = drive_for(voltage_V);
  return m == ControllerMode::inverse_pid_dob_ff ? correction_.forward(w) : w;
}

double Controller::voltage_for(double v, ControllerMode m) const noexcept {
  const double w = m == ControllerMode::inverse_pid_dob_ff ? correction_.inverse(v) : v;
  return comp_.voltage_for(inverse_(comp_.drive_inverse(w), output_.last_V()));
}

double Controller::law_offset(ControllerMode m, const Sample& s) noexcept {
  switch (m) {
    case ControllerMode::pid:
    case ControllerMode::inverse_pid: return 0.0;
    case ControllerMode::inverse_pid_dob: return -s.d_hat;
    case ControllerMode::inverse_pid_dob_ff: return s.v_ff - s.d_hat;
  }
  return 0.0;
}

void Controller::reset_steady_state(double r0) noexcept {
  comp_.reset_steady_state(output_.last_V());  // the drift's clock restarts before r0 is mapped
  const double x0 = std::clamp(inverse_(comp_.drive_inverse(comp_.rest_linear_input(r0, model_.G.dc_gain()))), cfg_.voltage_min_V,
                               cfg_.voltage_max_V);
  const double u0 = std::clamp(comp_.rest_voltage_for(x0), cfg_.voltage_min_V, cfg_.voltage_max_V);
  comp_.reset_steady_state(u0);
  const double w0 = drive_for(u0);
  comp_.reset_creep(w0);
  const double r0_lin = comp_.linear_output(r0);  // G(0) w0 unless r0 is out of reach
  const double v0 = r0_lin / model_.G.dc_gain();
  dob_.reset_steady_state(w0, model_.G.dc_gain());
  ff_.reset_steady_state(r0_lin);
  correction_.reset_steady_state(w0);
  output_.reset(u0);
  pid_.reset();
  mode_ = pending_mode_;
  pid_.set_gains(gains_[static_cast<size_t>(mode_)]);
  // At the nominal steady state d_hat = 0 and the feedforward alone supplies v0.
  const double target = mode_ == ControllerMode::pid                  ? u0
                        : mode_ == ControllerMode::inverse_pid_dob_ff ? w0 - v0
                                                                      : w0;
  pid_.align(0.0, target);
}

Controller::Sample Controller::observe(std::span<const double> preview, double y_lin) noexcept {
  Sample s;
  s.e_lin = comp_.linear_output(preview[0]) - y_lin;
  s.d_hat = dob_.estimate(y_lin);
  correction_.update(dob_.filtered_input());
  // The feedforward reads r[k + r_d] (r_d with the extra delay's whole samples), plus
  // the delay's fraction of a sample between two preview samples; the last one is held.
  const size_t last = preview.size() - 1, ahead = static_cast<size_t>(ff_.preview_samples());
  const double frac = comp_.extra_delay_fraction();
  const double r0 = preview[std::min(ahead, last)], r1 = preview[std::min(ahead + 1, last)];
  s.v_ff = ff_.step(comp_.linear_output(r0 + frac * (r1 - r0), static_cast<double>(ahead) + frac));
  return s;
}

void Controller::switch_mode_bumpless(const Sample& s) noexcept {
  // The new law starts from the voltage now applied.
  const double u_prev = output_.last_V();
  mode_ = pending_mode_;
  pid_.set_gains(gains_[static_cast<size_t>(mode_)]);
  const double target =
      mode_ == ControllerMode::pid ? u_prev : linear_input_for(u_prev, mode_) - law_offset(mode_, s);
  pid_.align(s.e_lin, target);
}

std::pair<double, double> Controller::apply_law(const Sample& s, ControlOutput& out) noexcept {
  const double c = pid_.output(s.e_lin);
  if (mode_ == ControllerMode::pid) {
    out.unclamped_V = c;
    out.voltage_V = output_.apply(c);
    out.v_command = model_.f(out.unclamped_V);
    return {c, out.voltage_V};
  }
  const double v = c + law_offset(mode_, s);
  out.v_command = v;
  out.unclamped_V = voltage_for(v, mode_);
  out.voltage_V = output_.apply(out.unclamped_V);
  const double achieved = linear_input_for(out.voltage_V, mode_);
  // Beyond f's range, the amplifier's reach or clamped by the output stage: the command was not achieved.
  if (std::abs(achieved - v) > 1e-9 * (1.0 + std::abs(v))) out.status = ControlOutput::Status::saturated;
  return {c, c + (achieved - v)};  // the clamped output in the PID's units
}

void Controller::commit(const Sample& s, double c, double applied_equivalent, double voltage_V) noexcept {
  pid_.commit(s.e_lin, c, applied_equivalent);
  const double w_applied = drive_for(voltage_V);
  dob_.commit(mode_ == ControllerMode::inverse_pid_dob_ff ? correction_.forward(w_applied) : w_applied);
  correction_.commit(w_applied);
  comp_.commit(voltage_V, w_applied);
}

ControlOutput Controller::step(std::span<const double> preview, double y) noexcept {
  ControlOutput out;
  const double r = preview.empty() ? NAN : preview[0];
  if (!std::isfinite(y) || !std::isfinite(r)) {
    out.voltage_V = out.unclamped_V = output_.last_V();
    out.status = ControlOutput::Status::invalid_input;
    // The held voltage is applied: the effects' states see it.
    comp_.commit(out.voltage_V, drive_for(out.voltage_V));
    return out;
  }
  out.error_um = r - y;
  const Sample s = observe(preview, comp_.linear_output(y));
  out.d_hat = s.d_hat;
  out.v_ff = s.v_ff;
  if (pending_mode_ != mode_) switch_mode_bumpless(s);
  const auto [c, applied_equivalent] = apply_law(s, out);
  commit(s, c, applied_equivalent, out.voltage_V);
  if (out.voltage_V != out.unclamped_V) out.status = ControlOutput::Status::saturated;
  return out;
}

}  // namespace pvcgel::control
