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

bool ControlLoop::base_reference(double t_run, double& value) const noexcept {
  const double t_loop = static_cast<double>(run_start_k_) * Ts_ + t_run;
  if (schedule_.value_at(t_loop, value)) return true;
  if (schedule_started_) {
    value = hold_value_;
    return false;
  }
  if (local_trajectory_) {
    value = trajectory_.at(std::max(0.0, t_run - safety_.soft_start_s));
    return true;
  }
  value = start_value_;  // nothing received yet: hold where the run started
  return true;
}

double ControlLoop::reference_at(double t_run) const noexcept {
  // Raised-cosine blend from where the actuator was to the setpoints, so
  // starting never steps the reference.
  double base = 0.0;
  base_reference(t_run, base);
  // Open loop has no measured position to blend from: voltage segments carry their own blend.
  const double T = target_.load(std::memory_order_relaxed) == LoopTarget::voltage ? 0.0 : safety_.soft_start_s;
  if (t_run < T) {
    const double s = 0.5 * (1.0 - std::cos(std::numbers::pi * t_run / T));
    return start_value_ + (base - start_value_) * s;
  }
  return base;
}

void ControlLoop::enter_ramp_down(FaultReason why) noexcept {
  pending_fault_ = why;
  if (why != FaultReason::none) fault_.store(why, std::memory_order_relaxed);
  state_.store(LoopState::ramp_down, std::memory_order_relaxed);
}

RejectReason ControlLoop::apply_command(const LoopInput& in, LoopState& state) noexcept {
  switch (in.command) {
    case CommandKind::arm:
      if (state != LoopState::disabled) return RejectReason::illegal_in_state;
      hal_.set_high_voltage(true);
      start_requested_ = false;
      state = LoopState::armed;
      return RejectReason::accepted;
    case CommandKind::start:
      if (state != LoopState::armed) return RejectReason::illegal_in_state;
      start_requested_ = true;
      return RejectReason::accepted;
    case CommandKind::stop:
      // Idempotent: stopping a loop that is not running is not an error.
      auto_start_ = local_trajectory_ = false;
      if (state == LoopState::armed || state == LoopState::running) {
        enter_ramp_down(FaultReason::none);
        state = LoopState::ramp_down;
      }
      return RejectReason::accepted;
    case CommandKind::reset:
      if (state != LoopState::fault) return RejectReason::illegal_in_state;
      auto_start_ = false;  // a remote reset leaves the rig DISABLED until armed again
      reset_requested_.store(true, std::memory_order_relaxed);
      return RejectReason::accepted;
    case CommandKind::set_mode:
      controller_.set_mode(static_cast<control::ControllerMode>(in.argument));
      return RejectReason::accepted;
    case CommandKind::set_target:
      if (state == LoopState::running || state == LoopState::ramp_down) return RejectReason::illegal_in_state;
      target_.store(static_cast<LoopTarget>(in.argument), std::memory_order_relaxed);
      schedule_.clear();
      schedule_started_ = false;
      return RejectReason::accepted;
    case CommandKind::clear:
      schedule_.clear();
      return RejectReason::accepted;
  }
  return RejectReason::unknown_command;
}

RejectReason ControlLoop::apply_segment(const LoopInput& in, LoopState state) noexcept {
  const SetpointSegment& seg = in.segment;
  if (seg.target != target_.load(std::memory_order_relaxed)) return RejectReason::target_mismatch;
  const double now_s = static_cast<double>(k_) * Ts_;
  const double current = target_.load(std::memory_order_relaxed) == LoopTarget::voltage ? setpoint_V_ : last_r_um_;
  // While running, the first value must not step from the setpoint in force
  // (unless blended slowly enough); otherwise the soft start blends anyway.
  const bool starts_now = seg.timing != SetpointSegment::Timing::at || seg.start_s <= now_s;
  if (state == LoopState::running && starts_now && seg.timing != SetpointSegment::Timing::append &&
      !start_step_allowed(seg, current, segment_value(seg, seg.start_s), limits_))
    return RejectReason::step_too_large;
  if (!schedule_.add(seg, now_s, current)) return RejectReason::queue_full;
  local_trajectory_ = false;  // received setpoints take over from the local trajectory
  return RejectReason::accepted;
}

void ControlLoop::take_inputs(LoopState& state) noexcept {
  for (int i = 0; i < LoopIo::kInputsPerCycle; ++i) {
    const LoopInput* in = io_->inputs.front();
    if (!in) break;
    const auto answer = [&](RejectReason r) {
      io_->outcomes.push(LoopOutcome{in->ticket, r, static_cast<std::uint8_t>(state)});
    };
    if (in->type == LoopInput::Type::command) {
      answer(apply_command(*in, state));
    } else if (in->ticket != refused_ticket_) {
      // A chunk is answered once: at its first refused piece, or after its last.
      const RejectReason r = apply_segment(*in, state);
      if (r != RejectReason::accepted) {
        answer(r);
        refused_ticket_ = in->ticket;
      } else if (in->last_piece) {
        answer(r);
      }
    }
    if (in->last_piece && in->ticket == refused_ticket_) refused_ticket_ = 0;
    io_->inputs.pop_front();
  }
}

CycleRecord ControlLoop::cycle(float latency_us, int consecutive_overruns) noexcept {
  CycleRecord rec;
  rec.seq = k_;
  rec.t_s = static_cast<double>(k_) * Ts_;
  rec.latency_us = latency_us;

  double y = NAN;
  const auto read_status = hal_.read_displacement(y);
  const FaultReason sensor = check_sensor(read_status, y);
  rec.y_um = y;

  LoopState state = state_.load(std::memory_order_relaxed);
  const bool stop = stop_requested_.load(std::memory_order_relaxed);
  if (io_) take_inputs(state);
  if (reset_requested_.exchange(false, std::memory_order_relaxed) && state == LoopState::fault && !stop) {
    // High voltage is already off and the output at 0 V; clear the fault and its counters.
    state = LoopState::disabled;
    pending_fault_ = FaultReason::none;
    fault_.store(FaultReason::none, std::memory_order_relaxed);
    same_reading_count_ = timeout_count_ = 0;
  }
  schedule_.advance(rec.t_s);
  const LoopTarget target = target_.load(std::memory_order_relaxed);
  const bool voltage_mode = target == LoopTarget::voltage;
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
      } else if (!(auto_start_ || start_requested_)) {
        // Waiting for a start command.
      } else if (sensor == FaultReason::none) {
        start_value_ = voltage_mode ? 0.0 : y;
        setpoint_V_ = 0.0;
        last_r_um_ = start_value_;
        run_start_k_ = k_;
        start_requested_ = false;
        schedule_started_ = false;
        if (!voltage_mode) controller_.reset_steady_state(y);
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
    double now_value = 0.0;
    if (schedule_.value_at(rec.t_s, now_value)) {
      schedule_started_ = true;
      hold_value_ = now_value;
    }
    double base = 0.0;
    const bool fresh = base_reference(t_run, base);
    FaultReason why = sensor;
    if (why == FaultReason::none && safety_.overrun_fault_after > 0 &&
        consecutive_overruns >= safety_.overrun_fault_after)
      why = FaultReason::overrun_storm;
    const double t_traj = t_run - safety_.soft_start_s;
    const bool local_dry = local_trajectory_ && t_traj > trajectory_.end_s();
    if (why == FaultReason::none && (local_dry || !fresh) && safety_.stale_setpoint == StaleSetpointPolicy::ramp_down)
      why = FaultReason::setpoint_stale;
    if (voltage_mode && why == FaultReason::sensor_timeout) why = FaultReason::none;  // open loop: y is only watched
    if (why != FaultReason::none) {
      enter_ramp_down(why);
      state = LoopState::ramp_down;
    } else if (stop || t_traj >= duration_s_) {
      finish_when_idle_ = true;
      enter_ramp_down(FaultReason::none);
      state = LoopState::ramp_down;
    } else if (voltage_mode) {
      // Open loop: the setpoint is the voltage, still slew-limited and clamped.
      const double wanted = reference_at(t_run);
      const double max_step = safety_.open_loop_slew_V_per_s * Ts_;
      setpoint_V_ += std::clamp(wanted - setpoint_V_, -max_step, max_step);
      u_V_ = std::clamp(setpoint_V_, controller_.config().voltage_min_V, controller_.config().voltage_max_V);
      rec.r_um = last_r_um_ = wanted;
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
    setpoint_V_ = u_V_;
    if (u_V_ <= 0.0) {
      hal_.set_high_voltage(false);
      state = pending_fault_ != FaultReason::none ? LoopState::fault : LoopState::disabled;
      if ((state == LoopState::disabled && finish_when_idle_) || (state == LoopState::fault && exit_on_fault_) || stop)
        finished_.store(true, std::memory_order_release);
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
  rec.mode = controller_.mode();
  rec.u_V = u_V_;
  rec.e_um = rec.r_um - y;
  rec.state = state;
  rec.fault = fault_.load(std::memory_order_relaxed);
  rec.high_voltage = state == LoopState::armed || state == LoopState::running || state == LoopState::ramp_down;
  rec.target = target;
  rec.chunk_seq = schedule_.chunk_at(rec.t_s);
  if (io_) {
    LoopSnapshot snap;
    snap.now_s = rec.t_s;
    snap.queued_until_s = schedule_.queued_until_s();
    snap.queued_segments = schedule_.size();
    snap.setpoint = rec.r_um;
    snap.target = target;
    snap.mode = rec.mode;
    snap.state = static_cast<std::uint8_t>(state);
    snap.fault = static_cast<std::uint8_t>(rec.fault);
    snap.high_voltage = rec.high_voltage;
    io_->snapshot.write(snap);
  }
  ++k_;
  return rec;
}

}  // namespace pvcgel::daemon
