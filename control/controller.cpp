#include "control/controller.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {

void check_range(const std::string& key, double v, double lo, double hi) {
  if (!(std::isfinite(v) && v >= lo && v <= hi)) {
    std::ostringstream os;
    os << "value " << v << " is outside the allowed range [" << lo << ", " << hi << "]";
    throw ConfigError(key, os.str());
  }
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

Controller::Controller(const HammersteinModel& model, const ControllerConfig& cfg)
    : cfg_(cfg),
      model_(model),
      plant_(DiscretePlantModel::make(model.G, cfg.sample_time_s, cfg.io_delay_samples)),
      inverse_([&] {
        check_range("controller.voltage_min_V", cfg.voltage_min_V, 0.0, 1000.0);
        check_range("controller.voltage_max_V", cfg.voltage_max_V, 0.0, 1000.0);
        if (!(cfg.voltage_max_V > cfg.voltage_min_V))
          throw ConfigError("controller.voltage_max_V", "must be above controller.voltage_min_V");
        // f must be monotone over the limits (this throws with the usable range if not);
        // the inverse itself spans as far as f stays monotone, so a request beyond the
        // limits shows up as an unclamped voltage the output stage then clamps.
        (void)PolynomialInverse(model.f, cfg.voltage_min_V, cfg.voltage_max_V);
        const auto turn = model.f.first_turnover(1000.0);
        const double upper = turn ? std::max(cfg.voltage_max_V, 0.999 * *turn) : 1000.0;
        return PolynomialInverse(model.f, 0.0, upper);
      }()),
      dob_(model, plant_, cfg.dob_lambda_s, cfg.dob_q_order),
      ff_(plant_),
      correction_(dob_, plant_, model.f(cfg.voltage_min_V), model.f(cfg.voltage_max_V),
                  cfg.learning_memory_s),
      mode_(cfg.mode),
      pending_mode_(cfg.mode) {
  check_range("controller.slew_limit_V_per_s", cfg.slew_limit_V_per_s, 0.0, 1e9);
  check_range("controller.antiwindup_tracking_time_s", cfg.antiwindup_tracking_time_s, 0.0, 1e3);
  check_range("controller.operating_point_um", cfg.operating_point_um, 0.0, 1e5);
  output_ = OutputStage(cfg.voltage_min_V, cfg.voltage_max_V, cfg.slew_limit_V_per_s, cfg.sample_time_s);

  const double dc = model_.G.dc_gain();
  const double u_op = std::clamp(inverse_(cfg.operating_point_um / dc), cfg.voltage_min_V, cfg.voltage_max_V);
  pid_plant_gain_ = model_.f.derivative(u_op);
  if (!(pid_plant_gain_ > 0.0)) throw ConfigError("controller.operating_point_um", "f' is not positive there");

  for (auto m : kAllModes) {
    const auto i = static_cast<size_t>(m);
    auto plant = design_plant(m);
    check_range("controller.tuning_gain_scale", cfg.tuning_gain_scale[i], 1e-3, 1e3);
    plant.b *= cfg.tuning_gain_scale[i];
    if (cfg.tuning) {
      const auto r = tune_pid(plant, cfg.sample_time_s, *cfg.tuning);
      gains_[i] = r.gains;
    } else {
      gains_[i] = cfg.gains[i];
    }
    check_gains(gains_[i], m, cfg.sample_time_s);
    margins_[i] = loop_margins(pid_transfer_function(gains_[i], cfg.sample_time_s), plant, cfg.sample_time_s);
    if (!margins_[i].stable()) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "closed loop of mode %s is unstable on the configured model (largest closed-loop pole "
                    "|z| = %.4f >= 1); reduce the gains",
                    to_string(m).data(), margins_[i].max_closed_loop_pole_abs);
      throw ConfigError("controller.pid." + std::string(to_string(m)), buf);
    }
  }
  pid_ = Pid(gains_[static_cast<size_t>(mode_)], cfg.sample_time_s, cfg.antiwindup_tracking_time_s);
  reset_steady_state(cfg.operating_point_um);
}

DiscreteTransferFunction Controller::design_plant(ControllerMode m) const {
  auto p = plant_.G_d;
  // Mode pid drives the voltage, so it sees f linearised at the operating point;
  // the inverse modes see G alone (the inverse cancels f on the model).
  if (m == ControllerMode::pid) p.b *= pid_plant_gain_;
  return p;
}

double Controller::linear_input_for(double voltage_V, ControllerMode m) const noexcept {
  const double w = model_.f(voltage_V);
  return m == ControllerMode::inverse_pid_dob_ff ? correction_.forward(w) : w;
}

double Controller::voltage_for(double v, ControllerMode m) const noexcept {
  const double w = m == ControllerMode::inverse_pid_dob_ff ? correction_.inverse(v) : v;
  return inverse_(w, output_.last_V());
}

void Controller::reset_steady_state(double r0) noexcept {
  const double v0 = r0 / model_.G.dc_gain();
  const double u0 = std::clamp(inverse_(v0), cfg_.voltage_min_V, cfg_.voltage_max_V);
  const double w0 = model_.f(u0);
  dob_.reset_steady_state(w0, model_.G.dc_gain());
  ff_.reset_steady_state(r0);
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

ControlOutput Controller::step(std::span<const double> preview, double y) noexcept {
  ControlOutput out;
  const double r = preview.empty() ? NAN : preview[0];
  if (!std::isfinite(y) || !std::isfinite(r)) {
    out.voltage_V = out.unclamped_V = output_.last_V();
    out.status = ControlOutput::Status::invalid_input;
    return out;
  }
  const double e = r - y;
  out.error_um = e;

  // Observers and the feedforward run in every mode so a switch finds them settled.
  out.d_hat = dob_.estimate(y);
  correction_.update(dob_.filtered_input());
  const size_t ahead = std::min(static_cast<size_t>(ff_.preview_samples()), preview.size() - 1);
  out.v_ff = ff_.step(preview[ahead]);

  auto extra = [&](ControllerMode m) {
    const bool dob = m == ControllerMode::inverse_pid_dob || m == ControllerMode::inverse_pid_dob_ff;
    return (m == ControllerMode::inverse_pid_dob_ff ? out.v_ff : 0.0) - (dob ? out.d_hat : 0.0);
  };

  if (pending_mode_ != mode_) {
    // Bumpless transfer: the new law starts from the voltage now applied.
    const double u_prev = output_.last_V();
    mode_ = pending_mode_;
    pid_.set_gains(gains_[static_cast<size_t>(mode_)]);
    const double target = mode_ == ControllerMode::pid ? u_prev : linear_input_for(u_prev, mode_) - extra(mode_);
    pid_.align(e, target);
  }

  const double c = pid_.output(e);
  double applied_equivalent;  // the clamped output in the PID's units
  if (mode_ == ControllerMode::pid) {
    out.unclamped_V = c;
    out.voltage_V = output_.apply(c);
    out.v_command = model_.f(out.unclamped_V);
    applied_equivalent = out.voltage_V;
  } else {
    const double v = c + extra(mode_);
    out.v_command = v;
    out.unclamped_V = voltage_for(v, mode_);
    out.voltage_V = output_.apply(out.unclamped_V);
    const double achieved = linear_input_for(out.voltage_V, mode_);
    applied_equivalent = c + (achieved - v);
    // Beyond f's range or clamped by the output stage: the command was not achieved.
    if (std::abs(achieved - v) > 1e-9 * (1.0 + std::abs(v))) out.status = ControlOutput::Status::saturated;
  }
  pid_.commit(e, c, applied_equivalent);
  const double w_applied = model_.f(out.voltage_V);
  dob_.commit(mode_ == ControllerMode::inverse_pid_dob_ff ? correction_.forward(w_applied) : w_applied);
  correction_.commit(w_applied);
  if (out.voltage_V != out.unclamped_V) out.status = ControlOutput::Status::saturated;
  return out;
}

}  // namespace pvcgel::control
