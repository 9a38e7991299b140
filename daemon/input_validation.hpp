#pragma once
/// @file
/// Checks on everything that arrives over DDS before it may reach the loop:
/// trajectory chunks and segments, and operator commands. Pure functions (no
/// DDS types, no I/O) so they can be unit-tested and fuzzed.

#include <algorithm>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "control/enum_table.hpp"
#include "daemon/setpoint_schedule.hpp"

namespace pvcgel::daemon {

/// Why an input was refused. Carried in CommandReply.reason and counted per
/// reason in Status.rejects_by_reason (the numbers are part of the DDS interface).
enum class RejectReason : std::uint8_t {
  accepted = 0,
  malformed,          ///< unknown kind/timing/target code, wrong number of values, empty client id, zero seq
  not_finite,         ///< NaN or infinity in a number
  out_of_range,       ///< a setpoint outside the configured range
  step_too_large,     ///< jump from the setpoint in force, or between samples, beyond the limit
  slope_too_large,    ///< rate of change beyond the limit
  in_the_past,        ///< start time already gone
  too_far_ahead,      ///< start time (or the queue's end) beyond the preview limit
  chunk_too_large,    ///< more samples than allowed per chunk
  bad_period,         ///< sample period below the loop period or above 1 s
  bad_duration,       ///< negative duration, or none where one is required
  target_mismatch,    ///< displacement setpoints in voltage mode or the other way round
  queue_full,         ///< no room in the loop's setpoint queue
  rate_limited,       ///< the client sends faster than allowed
  illegal_in_state,   ///< command not allowed in the current loop state
  unknown_command,    ///< command kind not known
  bad_argument,       ///< command argument out of range
  other_rig,          ///< addressed to another rig (counted, never answered)
  busy,               ///< back-pressure: the queue already reaches max_lead_s ahead; send again later (not counted as a rejection)
};
/// Stable names ("step_too_large", ...), part of the interface like the numbers.
inline constexpr auto kRejectReasonNames = enum_table<RejectReason::accepted, RejectReason::busy>(
    {"accepted", "malformed", "not_finite", "out_of_range", "step_too_large", "slope_too_large", "in_the_past",
     "too_far_ahead", "chunk_too_large", "bad_period", "bad_duration", "target_mismatch", "queue_full", "rate_limited",
     "illegal_in_state", "unknown_command", "bad_argument", "other_rig", "busy"});
constexpr const auto& names_of(RejectReason) noexcept { return kRejectReasonNames; }
constexpr std::string_view to_string(RejectReason r) noexcept { return kRejectReasonNames.to_string(r); }

/// Limits for incoming setpoints, from the [setpoints] configuration table.
struct SetpointLimits {
  double min_um = 0.0, max_um = 300.0;           ///< displacement setpoint range
  double max_step_um = 2.0;                      ///< largest jump without a blend
  double max_slope_um_per_s = 500.0;
  double min_V = 0.0, max_V = 1000.0;            ///< open-loop voltage setpoint range (then clamped again)
  double max_step_V = 30.0;                      ///< per sample; 30 V = 30 kV/s for one 1 ms cycle
  double max_slope_V_per_s = 30000.0;
  double max_lead_s = 10.0;                      ///< how far ahead of now a segment may start / the queue may reach
  double past_tolerance_s = 0.05;                ///< how late an absolute start may be
  int max_chunk_samples = 1024;
  double max_chunks_per_s = 200.0;               ///< per client, token bucket
  double max_commands_per_s = 50.0;
  double burst_s = 0.5;                          ///< bucket depth in seconds of the rate
};

/// A decoded Trajectory sample, without DDS types.
struct TrajectoryMessage {
  std::string_view rig_id, client_id;
  std::uint64_t chunk_seq = 0;
  std::uint8_t target = 0, kind = 0, timing = 0;
  double start_time_s = -1.0, period_s = 0.0, duration_s = 0.0, blend_s = 0.0;
  std::span<const double> values;
};

/// What the validator needs to know about the loop right now.
struct LoopView {
  double now_s = 0.0;
  double period_s = 1e-3;
  LoopTarget target = LoopTarget::displacement;
  double queued_until_s = -1e300;
  int queued_segments = 0;
};

/// Outcome of a check: the reason and, when refused, a sentence naming the
/// field and the value.
struct Verdict {
  RejectReason reason = RejectReason::accepted;
  std::string detail;
  [[nodiscard]] bool ok() const noexcept { return reason == RejectReason::accepted; }
};

/// Validate a trajectory message and cut it into loop segments (appended to
/// `out` only when accepted). The step from the setpoint in force is checked by
/// the loop itself when the first piece starts, since only it knows that value
/// exactly; `first_step_limits` below gives it the numbers.
Verdict validate_trajectory(const TrajectoryMessage& m, const SetpointLimits& limits, const LoopView& loop,
                            std::vector<SetpointSegment>& out);

/// Largest allowed jump at the start of `seg` from the value `from` (per the
/// limits, the target, and the segment's blend): the loop's check.
bool start_step_allowed(const SetpointSegment& seg, double from, double first_value, const SetpointLimits& limits) noexcept;

/// Command kinds of the DDS interface (Command.kind; 0 is not a command). The
/// names are the `pvcgel` subcommands that send them.
enum class CommandKind : std::uint8_t { arm = 1, start, stop, reset, set_mode, set_target, clear };
inline constexpr auto kCommandKindNames = enum_table<CommandKind::arm, CommandKind::clear>(
    {"arm", "start", "stop", "reset", "mode", "target", "clear"});
constexpr const auto& names_of(CommandKind) noexcept { return kCommandKindNames; }
constexpr std::string_view to_string(CommandKind k) noexcept { return kCommandKindNames.to_string(k); }

/// Validate a command's kind and argument (legality in the current state is the loop's call).
Verdict validate_command(std::uint8_t kind, std::uint8_t argument, std::string_view client_id, std::uint64_t seq);

/// Token bucket per client: `allow()` false when over the rate.
class RateLimiter final {
 public:
  RateLimiter(double rate_per_s, double burst_s) noexcept
      : rate_(rate_per_s), depth_(std::max(1.0, rate_per_s * burst_s)), tokens_(depth_) {}
  /// One message at time `t_s` (any monotonic clock).
  bool allow(double t_s) noexcept {
    tokens_ = std::min(depth_, tokens_ + (t_s - last_s_) * rate_);
    last_s_ = t_s;
    if (tokens_ < 1.0) return false;
    tokens_ -= 1.0;
    return true;
  }

 private:
  double rate_, depth_, tokens_, last_s_ = 0.0;
};

}  // namespace pvcgel::daemon
