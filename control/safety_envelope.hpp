#pragma once
/// @file
/// The safety envelope: the last check on what the real-time loop plays and
/// writes, whatever produced it (a local trajectory, a DDS chunk or segment, a
/// blend, an open-loop voltage target, a mode switch, a start or a reset).
/// Pure computation: the loop passes the period and calls it once per cycle.
///
/// Two governors, both first-order rate limiters with a range:
/// - the reference (um in closed loop, V in open loop): range, and a change per
///   cycle of at most min(max_step, max_slope * Ts); accepted setpoints never
///   reach either limit, so the governor acts only on a mistake (a client's, two
///   clients interleaving, or a bug in the schedule);
/// - the voltage written to the amplifier: range, and a slew limit per cycle
///   from the amplifier's rating (on by default), starting from the voltage
///   actually applied (bumpless). The fault ramp-down is the one path that
///   bypasses it, at its own configured rate.

#include <algorithm>
#include <cstdint>

namespace pvcgel::control {

/// Range and rate limits for one signal.
struct EnvelopeLimits {
  double min = 0.0, max = 0.0;
  double max_step = 0.0;   ///< largest change per cycle, in the signal's unit
  double max_slope = 0.0;  ///< unit per second
};

/// A range and a rate limit on one signal, applied cycle by cycle. Real-time
/// safe (noexcept, no allocation).
class RateGovernor final {
 public:
  RateGovernor() = default;
  RateGovernor(const EnvelopeLimits& limits, double period_s) noexcept
      : limits_(limits), step_(std::min(limits.max_step, limits.max_slope * period_s)) {}

  /// Start from `value` (clamped to the range): a bumpless start or reset.
  void reset(double value) noexcept { last_ = clamp(value); }
  /// The value to play this cycle for the requested one (NaN holds the last value).
  double apply(double requested) noexcept {
    last_ = next(last_, requested);
    if (last_ != requested) ++limited_cycles_;
    return last_;
  }
  /// What `apply` would give after `from`, without changing the state (preview).
  [[nodiscard]] double next(double from, double requested) const noexcept {
    if (!(requested == requested)) return from;  // NaN: hold
    return std::clamp(clamp(requested), from - step_, from + step_);
  }
  [[nodiscard]] double last() const noexcept { return last_; }
  /// Largest change per cycle.
  [[nodiscard]] double step() const noexcept { return step_; }
  [[nodiscard]] const EnvelopeLimits& limits() const noexcept { return limits_; }
  /// Cycles in which the governor changed the requested value (a mistake upstream).
  [[nodiscard]] std::uint64_t limited_cycles() const noexcept { return limited_cycles_; }

 private:
  [[nodiscard]] double clamp(double v) const noexcept { return std::clamp(v, limits_.min, limits_.max); }

  EnvelopeLimits limits_{};
  double step_ = 0.0;
  double last_ = 0.0;
  std::uint64_t limited_cycles_ = 0;
};

/// The envelope's configuration: reference limits for both targets and the
/// amplifier's voltage range and slew.
struct SafetyEnvelopeConfig {
  EnvelopeLimits displacement_um{0.0, 300.0, 2.0, 500.0};
  EnvelopeLimits voltage_setpoint_V{0.0, 1000.0, 30.0, 30000.0};
  double voltage_min_V = 0.0, voltage_max_V = 1000.0;
  double slew_V_per_s = 30000.0;  ///< the amplifier's rating (0 is refused at configuration)
};

/// Both governors of the loop.
class SafetyEnvelope final {
 public:
  SafetyEnvelope() = default;
  SafetyEnvelope(const SafetyEnvelopeConfig& c, double period_s) noexcept
      : displacement_(c.displacement_um, period_s), voltage_setpoint_(c.voltage_setpoint_V, period_s),
        output_({c.voltage_min_V, c.voltage_max_V, c.slew_V_per_s * period_s, c.slew_V_per_s}, period_s) {}

  /// The reference governor for the loop's target (displacement or voltage).
  RateGovernor& reference(bool voltage_target) noexcept { return voltage_target ? voltage_setpoint_ : displacement_; }
  /// The output (amplifier) governor.
  RateGovernor& output() noexcept { return output_; }
  [[nodiscard]] const RateGovernor& output() const noexcept { return output_; }
  /// Cycles in which either reference governor had to act.
  [[nodiscard]] std::uint64_t reference_limited_cycles() const noexcept {
    return displacement_.limited_cycles() + voltage_setpoint_.limited_cycles();
  }

 private:
  RateGovernor displacement_, voltage_setpoint_, output_;
};

}  // namespace pvcgel::control
