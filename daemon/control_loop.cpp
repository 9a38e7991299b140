#include "daemon/control_loop.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace pvcgel::daemon {

namespace {
constexpr std::string_view kStateNames[] = {"DISABLED", "ARMED", "RUNNING", "RAMP_DOWN", "FAULT"};
constexpr std::string_view kFaultNames[] = {"none",           "sensor_nan",      "sensor_out_of_range",
                                            "sensor_stale",   "sensor_timeout",  "amplifier_fault",
                                            "overrun_storm",  "setpoint_stale",  "hal_error"};
}  // namespace

std::string_view to_string(LoopState s) noexcept { return kStateNames[static_cast<size_t>(s)]; }
std::string_view to_string(FaultReason r) noexcept { return kFaultNames[static_cast<size_t>(r)]; }

ControlLoop::ControlLoop(hal::Hal& hal, control::Controller& controller, const Trajectory& trajectory,
                         const SafetyConfig& safety, double period_s, double duration_s)
    : hal_(hal), controller_(controller), trajectory_(trajectory), safety_(safety), Ts_(period_s),
      duration_s_(duration_s) {}

FaultReason ControlLoop::check_sensor(hal::HalStatus status, double y) noexcept {
  if (status == hal::HalStatus::timeout) {
    return ++timeout_count_ >= safety_.sensor_timeout_cycles ? FaultReason::sensor_timeout : FaultReason::none;
  }
  if (status != hal::HalStatus::ok) return FaultReason::hal_error;
  timeout_count_ = 0;
  if (!std::isfinite(y)) return FaultReason::sensor_nan;
  if (y < safety_.sensor_min_um || y > safety_.sensor_max_um) return FaultReason::sensor_out_of_range;
  same_reading_count_ = (y == last_y_) ? same_reading_count_ + 1 : 0;
  last_y_ = y;
  if (safety_.sensor_stale_cycles > 0 && same_reading_count_ >= safety_.sensor_stale_cycles)
    return FaultReason::sensor_stale;
  return FaultReason::none;
}

double ControlLoop::reference_at(double t) const noexcept {
  // Raised-cosine blend from where the actuator was to the trajectory's start,
  // so starting never steps the reference.
  const double T = safety_.soft_start_s;
  if (t < T) {
    const double s = 0.5 * (1.0 - std::cos(std::numbers::pi * t / T));
    return start_y_um_ + (trajectory_.at(0.0) - start_y_um_) * s;
  }
  return trajectory_.at(t - T);
}

void ControlLoop::enter_ramp_down(FaultReason why) noexcept {
  pending_fault_ = why;
  if (why != FaultReason::none) fault_.store(why, std::memory_order_relaxed);
  state_.store(LoopState::ramp_down, std::memory_order_relaxed);
}

CycleRecord ControlLoop::cycle(float latency_us, int consecutive_overruns) noexcept {
  CycleRecord rec;
  rec.seq = k_;
  rec.t_s = static_cast<double>(k_) * Ts_;
  rec.latency_us = latency_us;
  rec.mode = controller_.mode();

  double y = NAN;
  const auto read_status = hal_.read_displacement(y);
  const FaultReason sensor = check_sensor(read_status, y);
  rec.y_um = y;

  LoopState state = state_.load(std::memory_order_relaxed);
  const bool stop = stop_requested_.load(std::memory_order_relaxed);
  if (reset_requested_.exchange(false, std::memory_order_relaxed) && state == LoopState::fault && !stop) {
    // High voltage is already off and the output at 0 V; clear the fault and its counters.
    state = LoopState::disabled;
    pending_fault_ = FaultReason::none;
    fault_.store(FaultReason::none, std::memory_order_relaxed);
    same_reading_count_ = timeout_count_ = 0;
  }
  switch (state) {
    case LoopState::disabled:
      u_V_ = 0.0;
      if (auto_start_ && !stop && !finished_.load(std::memory_order_relaxed)) {
        hal_.set_high_voltage(true);
        state = LoopState::armed;
      }
      break;
    case LoopState::armed:
      u_V_ = 0.0;
      if (stop) {
        enter_ramp_down(FaultReason::none);
        state = LoopState::ramp_down;
      } else if (sensor == FaultReason::none) {
        start_y_um_ = y;
        run_start_k_ = k_;
        controller_.reset_steady_state(y);
        state = LoopState::running;
      } else if (read_status != hal::HalStatus::timeout || sensor == FaultReason::sensor_timeout) {
        enter_ramp_down(sensor);
        state = LoopState::ramp_down;
      }
      break;
    default:
      break;
  }

  if (state == LoopState::running) {
    const double t_run = static_cast<double>(k_ - run_start_k_) * Ts_;
    FaultReason why = sensor;
    if (why == FaultReason::none && safety_.overrun_fault_after > 0 &&
        consecutive_overruns >= safety_.overrun_fault_after)
      why = FaultReason::overrun_storm;
    const double t_traj = t_run - safety_.soft_start_s;
    if (why == FaultReason::none && t_traj > trajectory_.end_s() &&
        safety_.stale_setpoint == StaleSetpointPolicy::ramp_down)
      why = FaultReason::setpoint_stale;
    if (why != FaultReason::none) {
      enter_ramp_down(why);
      state = LoopState::ramp_down;
    } else if (stop || t_traj >= duration_s_) {
      enter_ramp_down(FaultReason::none);
      state = LoopState::ramp_down;
    } else if (read_status == hal::HalStatus::timeout) {
      // A single missed reading: hold the output, the controller state stays as it was.
      rec.r_um = last_r_um_ = reference_at(t_run);
    } else {
      const int n = std::min<int>(controller_.preview_samples() + 1, static_cast<int>(preview_.size()));
      for (int i = 0; i < n; ++i) preview_[static_cast<size_t>(i)] = reference_at(t_run + i * Ts_);
      const auto out = controller_.step(std::span<const double>(preview_.data(), static_cast<size_t>(n)), y);
      u_V_ = out.voltage_V;
      rec.r_um = last_r_um_ = preview_[0];
      rec.d_hat = out.d_hat;
    }
  }

  if (state == LoopState::ramp_down) {
    u_V_ = std::max(0.0, u_V_ - safety_.ramp_down_V_per_s * Ts_);
    if (u_V_ <= 0.0) {
      hal_.set_high_voltage(false);
      state = pending_fault_ != FaultReason::none ? LoopState::fault : LoopState::disabled;
      if (state == LoopState::disabled || exit_on_fault_ || stop) finished_.store(true, std::memory_order_release);
    }
  } else if (state == LoopState::fault || state == LoopState::disabled) {
    u_V_ = 0.0;
    if (stop) finished_.store(true, std::memory_order_release);
  }

  const auto write_status = hal_.write_voltage(u_V_);
  if (write_status == hal::HalStatus::device_fault && state != LoopState::fault &&
      state != LoopState::disabled && pending_fault_ == FaultReason::none) {
    enter_ramp_down(FaultReason::amplifier_fault);
    state = LoopState::ramp_down;
  }

  state_.store(state, std::memory_order_relaxed);
  if (state != LoopState::running) rec.r_um = last_r_um_;  // the last setpoint, for continuity
  rec.u_V = u_V_;
  rec.e_um = rec.r_um - y;
  rec.state = state;
  rec.fault = fault_.load(std::memory_order_relaxed);
  rec.high_voltage = state == LoopState::armed || state == LoopState::running || state == LoopState::ramp_down;
  ++k_;
  return rec;
}

}  // namespace pvcgel::daemon
