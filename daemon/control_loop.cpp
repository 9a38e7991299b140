#include "daemon/control_loop.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace pvcgel::daemon {

ControlLoop::ControlLoop(hal::Hal& hal, control::Controller& controller, const Trajectory& trajectory,
                         const SafetyConfig& safety, double period_s, double duration_s)
    : hal_(hal), controller_(controller), trajectory_(trajectory), safety_(safety), Ts_(period_s),
      duration_s_(duration_s) {
  set_limits(SetpointLimits{});
}

void ControlLoop::set_limits(const SetpointLimits& l) noexcept {
  limits_ = l;
  const auto& cc = controller_.config();
  control::SafetyEnvelopeConfig c;
  c.displacement_um = {l.min_um, l.max_um, l.max_step_um, l.max_slope_um_per_s};
  c.voltage_setpoint_V = {std::max(l.min_V, cc.voltage_min_V), std::min(l.max_V, cc.voltage_max_V), l.max_step_V,
                          std::min(l.max_slope_V_per_s, safety_.open_loop_slew_V_per_s)};
  c.voltage_min_V = cc.voltage_min_V;
  c.voltage_max_V = cc.voltage_max_V;
  c.slew_V_per_s = safety_.output_slew_V_per_s;
  envelope_ = control::SafetyEnvelope(c, Ts_);
}

// ---- read ------------------------------------------------------------------

ControlLoop::Reading ControlLoop::read_sensor() noexcept {
  Reading in;
  in.y_um = NAN;
  in.status = hal_.read_displacement(in.y_um);
  in.fault = check_sensor(in.status, in.y_um);
  return in;
}

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

// ---- update: inputs --------------------------------------------------------

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

void ControlLoop::enter_ramp_down(FaultReason why, LoopState& state) noexcept {
  pending_fault_ = why;
  if (why != FaultReason::none) fault_.store(why, std::memory_order_relaxed);
  state = LoopState::ramp_down;
  state_.store(state, std::memory_order_relaxed);
}

RejectReason ControlLoop::apply_command(const LoopInput& in, LoopState& state) noexcept {
  switch (in.command) {
    case CommandKind::arm:
      if (state != LoopState::disabled) return RejectReason::illegal_in_state;
      // A fault's cause still present (the sensor, the amplifier, the link) keeps the rig disarmed.
      if (cause_present_ != FaultReason::none) return RejectReason::illegal_in_state;
      if (!set_high_voltage(true, state)) return RejectReason::illegal_in_state;
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
      if (state == LoopState::armed || state == LoopState::running) enter_ramp_down(FaultReason::none, state);
      return RejectReason::accepted;
    case CommandKind::reset:
      if (state != LoopState::fault) return RejectReason::illegal_in_state;
      reset_requested_.store(true, std::memory_order_relaxed);
      return RejectReason::accepted;
    case CommandKind::set_mode: {
      // Checked by the bridge already; an input from elsewhere with an unknown mode is refused, never cast.
      const auto mode = from_wire<control::ControllerMode>(in.argument);
      if (!mode) return RejectReason::bad_argument;
      controller_.set_mode(*mode);
      return RejectReason::accepted;
    }
    case CommandKind::set_target: {
      const auto target = from_wire<LoopTarget>(in.argument);
      if (!target) return RejectReason::bad_argument;
      if (state == LoopState::running || state == LoopState::ramp_down) return RejectReason::illegal_in_state;
      target_.store(*target, std::memory_order_relaxed);
      schedule_.clear();
      schedule_started_ = false;
      return RejectReason::accepted;
    }
    case CommandKind::clear:
      schedule_.clear();
      return RejectReason::accepted;
  }
  return RejectReason::unknown_command;
}

RejectReason ControlLoop::apply_segment(const LoopInput& in, LoopState state) noexcept {
  const SetpointSegment& seg = in.segment;
  const bool first_piece = !seg.continues;
  if (seg.target != target_.load(std::memory_order_relaxed)) return RejectReason::target_mismatch;
  const double now_s = static_cast<double>(k_) * Ts_;
  const double current = target_.load(std::memory_order_relaxed) == LoopTarget::voltage ? setpoint_V_ : last_r_um_;
  // While running, a chunk's first value must not step from the setpoint in
  // force where it starts (appended: the end of the queue), unless blended
  // slowly enough; otherwise the soft start blends anyway. Later pieces of a
  // chunk continue it (checked by the validator).
  if (state == LoopState::running && first_piece) {
    const double tail = schedule_.queued_until_s();
    const bool after_tail = seg.timing == SetpointSegment::Timing::append && std::isfinite(tail) && tail > now_s;
    const double start = seg.timing == SetpointSegment::Timing::at ? seg.start_s : now_s;
    double from = current;
    if (after_tail) from = schedule_.tail_value();  // the curve it continues (a running blend carries on)
    else if (start > now_s && !schedule_.value_at(start - 1e-9, from)) from = current;
    if (!start_step_allowed(seg, from, segment_value(seg, seg.start_s), limits_)) return RejectReason::step_too_large;
  }
  if (!schedule_.add(seg, now_s, current)) return RejectReason::queue_full;
  local_trajectory_ = false;  // received setpoints take over from the local trajectory
  return RejectReason::accepted;
}

void ControlLoop::take_inputs(LoopState& state) noexcept {
  for (int i = 0; i < LoopIo::kInputsPerCycle; ++i) {
    const LoopInput* in = io_->inputs.front();
    if (!in) break;
    const auto answer = [&](RejectReason r) {
      const auto cause = r == RejectReason::accepted ? FaultReason::none
                         : state == LoopState::fault ? fault_.load(std::memory_order_relaxed)
                                                     : cause_present_;
      io_->outcomes.push(LoopOutcome{in->ticket, r, state, cause});
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

// ---- update: transition ----------------------------------------------------

void ControlLoop::transition(LoopState& state, const Reading& in, bool stop) noexcept {
  if (reset_requested_.exchange(false, std::memory_order_relaxed) && state == LoopState::fault && !stop) {
    // FAULT -> DISABLED: high voltage is already off and the output at 0 V;
    // clear the fault and its counters. Never re-arm or restart by itself.
    state = LoopState::disabled;
    auto_start_ = false;
    pending_fault_ = FaultReason::none;
    fault_.store(FaultReason::none, std::memory_order_relaxed);
    same_reading_count_ = timeout_count_ = write_timeout_count_ = 0;
  }
  const bool voltage_mode = target_.load(std::memory_order_relaxed) == LoopTarget::voltage;
  if (state == LoopState::disabled) {
    if (auto_start_ && !stop && !finished_.load(std::memory_order_relaxed) && set_high_voltage(true, state))
      state = LoopState::armed;
  } else if (state == LoopState::armed) {
    if (stop) {
      enter_ramp_down(FaultReason::none, state);
    } else if (!(auto_start_ || start_requested_)) {
      // Waiting for a start command.
    } else if (in.fault == FaultReason::none) {
      start_running(in, voltage_mode);
      state = LoopState::running;
    } else if (in.status != hal::HalStatus::timeout || in.fault == FaultReason::sensor_timeout) {
      enter_ramp_down(in.fault, state);
    }
  }
}

void ControlLoop::start_running(const Reading& in, bool voltage_mode) noexcept {
  // Bumpless: the reference starts at the measured position (clamped to the
  // range), the voltage at the one actually applied (the output governor's last).
  auto& ref = envelope_.reference(voltage_mode);
  ref.reset(voltage_mode ? 0.0 : in.y_um);
  start_value_ = ref.last();
  setpoint_V_ = 0.0;
  last_r_um_ = start_value_;
  run_start_k_ = k_;
  start_requested_ = false;
  schedule_started_ = false;
  u_requested_V_ = envelope_.output().last();
  if (!voltage_mode) {
    controller_.reset_steady_state(start_value_);
    controller_.set_applied_voltage(envelope_.output().last());
  }
}

// ---- update: compute -------------------------------------------------------

FaultReason ControlLoop::running_fault(const Reading& in, int consecutive_overruns, bool fresh,
                                       double t_traj) const noexcept {
  FaultReason why = in.fault;
  if (why == FaultReason::none && safety_.overrun_fault_after > 0 && consecutive_overruns >= safety_.overrun_fault_after)
    why = FaultReason::overrun_storm;
  const bool local_dry = local_trajectory_ && t_traj > trajectory_.end_s();
  if (why == FaultReason::none && (local_dry || !fresh) && safety_.stale_setpoint == StaleSetpointPolicy::ramp_down)
    why = FaultReason::setpoint_stale;
  const bool voltage_mode = target_.load(std::memory_order_relaxed) == LoopTarget::voltage;
  if (voltage_mode && why == FaultReason::sensor_timeout) why = FaultReason::none;  // open loop: y is only watched
  return why;
}

void ControlLoop::governed_preview(double t_run, int n) noexcept {
  // The preview is what the governor will play if the setpoints stay as they are.
  auto& ref = envelope_.reference(false);
  preview_[0] = ref.apply(reference_at(t_run));
  for (int i = 1; i < n; ++i)
    preview_[static_cast<size_t>(i)] = ref.next(preview_[static_cast<size_t>(i - 1)], reference_at(t_run + i * Ts_));
}

void ControlLoop::compute(LoopState& state, const Reading& in, int consecutive_overruns, bool stop,
                          CycleRecord& rec) noexcept {
  const double t_run = static_cast<double>(k_ - run_start_k_) * Ts_;
  double now_value = 0.0;
  if (schedule_.value_at(rec.t_s, now_value)) {
    schedule_started_ = true;
    hold_value_ = now_value;
  }
  double base = 0.0;
  const bool fresh = base_reference(t_run, base);
  const double t_traj = t_run - safety_.soft_start_s;
  const FaultReason why = running_fault(in, consecutive_overruns, fresh, t_traj);
  if (why != FaultReason::none) return enter_ramp_down(why, state);
  if (stop || t_traj >= duration_s_) {
    finish_when_idle_ = true;
    return enter_ramp_down(FaultReason::none, state);
  }
  if (target_.load(std::memory_order_relaxed) == LoopTarget::voltage) {
    // Open loop: the setpoint is the voltage, through the reference governor, then the output's.
    setpoint_V_ = envelope_.reference(true).apply(reference_at(t_run));
    u_requested_V_ = setpoint_V_;
    rec.r_um = last_r_um_ = setpoint_V_;
  } else if (in.status == hal::HalStatus::timeout) {
    // A single missed reading: hold the output, the controller state stays as it was.
    rec.r_um = last_r_um_ = envelope_.reference(false).apply(reference_at(t_run));
  } else {
    const int n = std::min<int>(controller_.preview_samples() + 1, static_cast<int>(preview_.size()));
    governed_preview(t_run, n);
    const auto out = controller_.step(std::span<const double>(preview_.data(), static_cast<size_t>(n)), in.y_um);
    u_requested_V_ = out.voltage_V;
    rec.r_um = last_r_um_ = preview_[0];
    rec.d_hat = out.d_hat;
  }
}

// ---- update: govern (the envelope on the output) ---------------------------

void ControlLoop::govern(LoopState& state, bool stop) noexcept {
  auto& out = envelope_.output();
  if (hv_disable_pending_) set_high_voltage(false, state);
  if (state == LoopState::ramp_down) {
    // The fault/stop ramp is the one exception to the slew limit: its own rate, down only.
    u_V_ = std::max(0.0, out.last() - safety_.ramp_down_V_per_s * Ts_);
    out.reset(u_V_);
    setpoint_V_ = u_V_;
    if (u_V_ > 0.0) return;
    set_high_voltage(false, state);
    state = pending_fault_ != FaultReason::none ? LoopState::fault : LoopState::disabled;
    if ((state == LoopState::disabled && finish_when_idle_) || (state == LoopState::fault && exit_on_fault_) || stop)
      finished_.store(true, std::memory_order_release);
    return;
  }
  if (state != LoopState::running) u_requested_V_ = 0.0;
  u_V_ = out.apply(u_requested_V_);
  // The controller must know what was really applied (anti-windup, DOB).
  if (state == LoopState::running && u_V_ != u_requested_V_ && target_.load(std::memory_order_relaxed) == LoopTarget::displacement)
    controller_.set_applied_voltage(u_V_);
  if ((state == LoopState::fault || state == LoopState::disabled) && stop) finished_.store(true, std::memory_order_release);
}

// ---- write -----------------------------------------------------------------

FaultReason ControlLoop::check_actuator(hal::HalStatus status, FaultReason on_failure) noexcept {
  if (status == hal::HalStatus::ok) {
    write_timeout_count_ = 0;
    return FaultReason::none;
  }
  actuator_failures_.fetch_add(1, std::memory_order_relaxed);
  // The amplifier (or its interlock) refusing a write is its own fault; refusing the enable is not.
  if (status == hal::HalStatus::device_fault && on_failure == FaultReason::actuator_write_failed)
    return FaultReason::amplifier_fault;
  if (status == hal::HalStatus::timeout && ++write_timeout_count_ < safety_.sensor_timeout_cycles) return FaultReason::none;
  return on_failure;
}

bool ControlLoop::set_high_voltage(bool on, LoopState& state) noexcept {
  const FaultReason f =
      check_actuator(hal_.set_high_voltage(on), on ? FaultReason::hv_enable_failed : FaultReason::hv_disable_failed);
  hv_disable_pending_ = !on && f != FaultReason::none;
  if (f == FaultReason::none) return true;
  if (on) hv_disable_pending_ = hal_.set_high_voltage(false) != hal::HalStatus::ok;  // undo the half-done arm
  if (state == LoopState::fault) {
    fault_.store(f, std::memory_order_relaxed);
  } else if (pending_fault_ == FaultReason::none) {
    enter_ramp_down(f, state);  // through the ramp (immediate at 0 V) to FAULT, so a --duration run ends
  }
  return false;
}

void ControlLoop::write_actuator(LoopState& state) noexcept {
  actuator_cause_ = check_actuator(hal_.write_voltage(u_V_), FaultReason::actuator_write_failed);
  if (actuator_cause_ == FaultReason::none || state == LoopState::fault || state == LoopState::disabled ||
      pending_fault_ != FaultReason::none)
    return;
  enter_ramp_down(actuator_cause_, state);
  // The amplifier cannot be commanded down: cut high voltage now instead of ramping.
  if (actuator_cause_ == FaultReason::actuator_write_failed) set_high_voltage(false, state);
}

// ---- publish ---------------------------------------------------------------

void ControlLoop::publish(CycleRecord& rec, LoopState state, LoopTarget target) noexcept {
  state_.store(state, std::memory_order_relaxed);
  if (state != LoopState::running) rec.r_um = last_r_um_;  // the last setpoint, for continuity
  rec.mode = controller_.mode();
  rec.u_V = u_V_;
  rec.e_um = rec.r_um - rec.y_um;
  rec.state = state;
  rec.fault = fault_.load(std::memory_order_relaxed);
  rec.high_voltage = hal_.health().high_voltage_enabled;  // what the HAL says, not what the state implies
  rec.target = target;
  rec.chunk_seq = schedule_.chunk_at(rec.t_s);
  if (!io_) return;
  LoopSnapshot snap;
  snap.now_s = rec.t_s;
  snap.queued_until_s = schedule_.queued_until_s();
  snap.queued_segments = schedule_.size();
  snap.setpoint = rec.r_um;
  snap.target = target;
  snap.mode = rec.mode;
  snap.state = state;
  snap.fault = rec.fault;
  snap.high_voltage = rec.high_voltage;
  io_->snapshot.write(snap);
}

// ---- the cycle: read, update, write ----------------------------------------

CycleRecord ControlLoop::cycle(float latency_us, int consecutive_overruns) noexcept {
  CycleRecord rec;
  rec.seq = k_;
  rec.t_s = static_cast<double>(k_) * Ts_;
  rec.latency_us = latency_us;

  const Reading in = read_sensor();
  rec.y_um = in.y_um;

  LoopState state = state_.load(std::memory_order_relaxed);
  const bool stop = stop_requested_.load(std::memory_order_relaxed);
  cause_present_ = in.fault != FaultReason::none ? in.fault
                   : hv_disable_pending_         ? FaultReason::hv_disable_failed
                                                 : actuator_cause_;
  if (io_) take_inputs(state);
  transition(state, in, stop);
  schedule_.advance(rec.t_s);
  if (state == LoopState::running) compute(state, in, consecutive_overruns, stop, rec);
  govern(state, stop);

  write_actuator(state);

  publish(rec, state, target_.load(std::memory_order_relaxed));
  ++k_;
  return rec;
}

}  // namespace pvcgel::daemon
