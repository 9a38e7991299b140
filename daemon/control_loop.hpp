#pragma once
/// @file
/// One cycle of the real-time loop, as ros2_control's read / update / write:
/// read and check the sensor; take inputs, transition, compute, govern (the
/// safety envelope); write and check the actuator; publish. No threads or
/// clocks here (see realtime_thread.hpp), so every path can be tested cycle by cycle.

#include <array>
#include <atomic>
#include <cstdint>
#include <string_view>

#include "control/controller.hpp"
#include "control/safety_envelope.hpp"
#include "daemon/loop_io.hpp"
#include "daemon/loop_state.hpp"
#include "daemon/trajectory.hpp"
#include "hal/hal.hpp"

namespace pvcgel::daemon {

/// What to do when the setpoint source runs out.
enum class StaleSetpointPolicy : std::uint8_t { hold, ramp_down };
inline constexpr auto kStaleSetpointPolicyNames =
    enum_table<StaleSetpointPolicy::hold, StaleSetpointPolicy::ramp_down>({"hold", "ramp_down"});
constexpr const auto& names_of(StaleSetpointPolicy) noexcept { return kStaleSetpointPolicyNames; }
constexpr std::string_view to_string(StaleSetpointPolicy p) noexcept { return kStaleSetpointPolicyNames.to_string(p); }

/// Safety limits, validated at configuration time.
struct SafetyConfig {
  double ramp_down_V_per_s = 500.0;   ///< output ramp on stop/fault
  double sensor_min_um = -50.0;       ///< plausible sensor range
  double sensor_max_um = 1000.0;
  int sensor_stale_cycles = 50;       ///< identical readings before a fault (0: off)
  int sensor_timeout_cycles = 3;      ///< consecutive timeouts before a fault
  int overrun_fault_after = 10;       ///< consecutive overruns before a fault (0: never)
  StaleSetpointPolicy stale_setpoint = StaleSetpointPolicy::hold;
  double soft_start_s = 2.0;          ///< blend from the measured position to the trajectory
  double open_loop_slew_V_per_s = 30000.0;  ///< slew limit on voltage setpoints (open-loop mode)
  /// Slew limit on every voltage written (the amplifier's rating), except the
  /// fault ramp-down which runs at ramp_down_V_per_s. Always on.
  double output_slew_V_per_s = 30000.0;
};

/// One row of telemetry / recording. Row k: y measured at the start of cycle k
/// and the voltage then applied and held until cycle k+1.
struct CycleRecord {
  std::uint64_t seq = 0;
  double t_s = 0.0;
  double u_V = 0.0;
  double y_um = 0.0;
  double r_um = 0.0;
  double e_um = 0.0;
  double d_hat = 0.0;
  float latency_us = 0.0f;  ///< wake-up latency of this cycle
  control::ControllerMode mode = control::ControllerMode::pid;
  LoopState state = LoopState::disabled;
  FaultReason fault = FaultReason::none;
  bool high_voltage = false;
  LoopTarget target = LoopTarget::displacement;
  std::uint64_t chunk_seq = 0;  ///< the received trajectory chunk that set r (0: none / local)
  std::int64_t stamp_ns = 0;    ///< CLOCK_REALTIME at wake-up (set by the timing thread)
};

/// The loop's per-cycle logic. `cycle()` is real-time safe.
class ControlLoop final {
 public:
  /// @param duration_s  run length of the trajectory (after the soft start); infinity: until stopped
  ControlLoop(hal::Hal& hal, control::Controller& controller, const Trajectory& trajectory,
              const SafetyConfig& safety, double period_s, double duration_s);

  /// Run one cycle. `consecutive_overruns` comes from the timing thread.
  CycleRecord cycle(float latency_us, int consecutive_overruns) noexcept;
  /// Ask for a clean stop (ramp down, disable, finish). Any thread.
  void request_stop() noexcept { stop_requested_.store(true, std::memory_order_relaxed); }
  /// Explicit reset: FAULT -> DISABLED with high voltage off (ignored in other
  /// states). Never re-arms or restarts by itself: arming again is a command,
  /// refused while the fault's cause is present. Any thread.
  void request_reset() noexcept { reset_requested_.store(true, std::memory_order_relaxed); }
  /// True once the loop has come to rest (DISABLED after a stop, or FAULT when
  /// `exit_on_fault`) and the caller may end the thread.
  [[nodiscard]] bool finished() const noexcept { return finished_.load(std::memory_order_acquire); }
  /// Current state and fault (any thread).
  [[nodiscard]] LoopState state() const noexcept { return state_.load(std::memory_order_relaxed); }
  [[nodiscard]] FaultReason fault() const noexcept { return fault_.load(std::memory_order_relaxed); }
  /// Leave the loop finished after a fault instead of waiting in FAULT for a reset.
  void set_exit_on_fault(bool v) noexcept { exit_on_fault_ = v; }
  /// Arm and start by itself (a trajectory was given). Otherwise the loop idles
  /// DISABLED at 0 V until a setpoint source starts it.
  void set_auto_start(bool v) noexcept { auto_start_ = local_trajectory_ = v; }
  /// Take commands and setpoint segments from `io` (the DDS bridge), check
  /// them against `limits`, answer through `io.outcomes`, and publish a
  /// snapshot every cycle. Call before the loop runs.
  void attach_io(LoopIo& io, const SetpointLimits& limits) noexcept {
    io_ = &io;
    set_limits(limits);
  }
  /// The `[setpoints]` limits the safety envelope enforces on every reference
  /// played (also local trajectories). Call before the loop runs.
  void set_limits(const SetpointLimits& limits) noexcept;
  /// Non-ok results of write_voltage and set_high_voltage so far (any thread).
  [[nodiscard]] std::uint64_t actuator_failures() const noexcept {
    return actuator_failures_.load(std::memory_order_relaxed);
  }
  /// The envelope (for tests and the stop summary: how often it had to act).
  [[nodiscard]] const control::SafetyEnvelope& envelope() const noexcept { return envelope_; }
  /// Displacement (closed loop) or voltage (open loop) setpoints.
  [[nodiscard]] LoopTarget target() const noexcept { return target_.load(std::memory_order_relaxed); }

 private:
  /// What the read step found this cycle.
  struct Reading {
    double y_um = 0.0;
    hal::HalStatus status = hal::HalStatus::ok;
    FaultReason fault = FaultReason::none;
  };
  Reading read_sensor() noexcept;
  FaultReason check_sensor(hal::HalStatus status, double y) noexcept;
  /// Turns a write_voltage or set_high_voltage result into a fault (none when ok).
  FaultReason check_actuator(hal::HalStatus status, FaultReason on_failure) noexcept;
  /// set_high_voltage with its result checked; false (and a fault started) on failure.
  bool set_high_voltage(bool on, LoopState& state) noexcept;
  void transition(LoopState& state, const Reading& in, bool stop) noexcept;
  void start_running(const Reading& in, bool voltage_mode) noexcept;
  void compute(LoopState& state, const Reading& in, int consecutive_overruns, bool stop, CycleRecord& rec) noexcept;
  FaultReason running_fault(const Reading& in, int consecutive_overruns, bool fresh, double t_traj) const noexcept;
  /// The reference for the controller, through the envelope, with preview.
  void governed_preview(double t_run, int n) noexcept;
  void govern(LoopState& state, bool stop) noexcept;
  void write_actuator(LoopState& state) noexcept;
  void publish(CycleRecord& rec, LoopState state, LoopTarget target) noexcept;
  /// The setpoint before the soft-start blend; false when the received
  /// setpoints ran dry (the stale-setpoint case).
  bool base_reference(double t_run, double& value) const noexcept;
  double reference_at(double t_run) const noexcept;
  void enter_ramp_down(FaultReason why, LoopState& state) noexcept;
  /// Apply queued inputs; `state` may change (arm, stop, reset).
  void take_inputs(LoopState& state) noexcept;
  RejectReason apply_command(const LoopInput& in, LoopState& state) noexcept;
  RejectReason apply_segment(const LoopInput& in, LoopState state) noexcept;

  hal::Hal& hal_;
  control::Controller& controller_;
  const Trajectory& trajectory_;
  SafetyConfig safety_;
  double Ts_;
  double duration_s_;
  std::uint64_t k_ = 0;
  std::uint64_t run_start_k_ = 0;
  double start_y_um_ = 0.0;
  double u_V_ = 0.0;
  double last_y_ = 0.0;
  double last_r_um_ = 0.0;
  int same_reading_count_ = 0;
  int timeout_count_ = 0;
  FaultReason pending_fault_ = FaultReason::none;
  bool exit_on_fault_ = false;
  bool auto_start_ = true;
  bool local_trajectory_ = true;    // play `trajectory_` (until received setpoints take over)
  bool start_requested_ = false;    // a start command in ARMED
  bool finish_when_idle_ = false;   // the ramp-down ends the run (duration reached, shutdown)
  bool schedule_started_ = false;   // received setpoints have played: a gap is a stale setpoint
  double start_value_ = 0.0;        // where the soft start blends from (um, or V in voltage mode)
  double hold_value_ = 0.0;         // setpoint held after received setpoints ran dry
  double setpoint_V_ = 0.0;         // open-loop voltage after the slew limit
  double u_requested_V_ = 0.0;      // what the control law (or open-loop setpoint) asked for this cycle
  bool ramping_ = false;            // the fault/stop ramp owns the output this cycle (bypasses the slew limit)
  int write_timeout_count_ = 0;
  FaultReason cause_present_ = FaultReason::none;  // a fault's cause seen this cycle (sensor or actuator)
  FaultReason actuator_cause_ = FaultReason::none; // the last write's problem, kept until a write succeeds
  bool hv_disable_pending_ = false;                // disabling failed: retry every cycle
  std::uint32_t last_ticket_ = 0;                  // the chunk whose pieces are arriving
  control::SafetyEnvelope envelope_{};
  std::atomic<std::uint64_t> actuator_failures_{0};
  LoopIo* io_ = nullptr;
  std::uint32_t refused_ticket_ = 0;  // the rest of this chunk is dropped unanswered
  SetpointLimits limits_{};
  SetpointSchedule schedule_{};
  std::atomic<LoopTarget> target_{LoopTarget::displacement};
  std::atomic<LoopState> state_{LoopState::disabled};
  std::atomic<FaultReason> fault_{FaultReason::none};
  std::atomic<bool> stop_requested_{false};
  std::atomic<bool> reset_requested_{false};
  std::atomic<bool> finished_{false};
  std::array<double, 16> preview_{};
};

}  // namespace pvcgel::daemon
