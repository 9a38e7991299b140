#pragma once
/// @file
/// What crosses between the DDS thread and the real-time loop: inputs
/// (commands and setpoint segments, in arrival order), the loop's verdict on
/// each, and a snapshot of the loop for validation and status. All lock-free;
/// the loop never waits on DDS.

#include <cstdint>

#include "control/controller.hpp"
#include "daemon/input_validation.hpp"
#include "daemon/loop_state.hpp"
#include "daemon/setpoint_schedule.hpp"
#include "daemon/spsc_ring.hpp"
#include "daemon/triple_buffer.hpp"

namespace pvcgel::daemon {

/// One input for the loop. `ticket` lets the DDS thread match the outcome to
/// the client and sequence number it came with.
struct LoopInput {
  enum class Type : std::uint8_t { command, segment };
  Type type = Type::command;
  CommandKind command = CommandKind::stop;
  std::uint8_t argument = 0;
  /// Last piece of a trajectory chunk: the loop answers once per chunk.
  bool last_piece = true;
  std::uint32_t ticket = 0;
  SetpointSegment segment;
};

/// The loop's answer to one input (a whole chunk: its first refusal, or
/// acceptance after its last piece).
struct LoopOutcome {
  std::uint32_t ticket = 0;
  RejectReason reason = RejectReason::accepted;
  /// For refusals: the state the loop was in, and the fault whose cause is
  /// still present (an arm refused because of it).
  LoopState state = LoopState::disabled;
  FaultReason cause = FaultReason::none;
};

/// What the DDS thread needs to know about the loop, every cycle.
struct LoopSnapshot {
  double now_s = 0.0;
  double queued_until_s = -1e300;
  double setpoint = 0.0;
  int queued_segments = 0;
  LoopTarget target = LoopTarget::displacement;
  control::ControllerMode mode = control::ControllerMode::pid;
  LoopState state = LoopState::disabled;
  FaultReason fault = FaultReason::none;
  bool high_voltage = false;
};

/// The three channels, owned by the daemon and shared by reference.
struct LoopIo {
  /// Bounded: 128 inputs, at most `kInputsPerCycle` taken per cycle.
  SpscRing<LoopInput, 128> inputs;
  SpscRing<LoopOutcome, 256> outcomes;
  TripleBuffer<LoopSnapshot> snapshot;
  static constexpr int kInputsPerCycle = 16;
};

}  // namespace pvcgel::daemon
