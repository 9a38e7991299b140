#pragma once
/// @file
/// The loop's safety state and fault reason, with their checked name tables.
/// Their own header because the loop, its I/O channels, the DDS messages and
/// the tools all carry them (as enums, never as raw octets).

#include <cstdint>
#include <string_view>

#include "control/enum_table.hpp"

namespace pvcgel::daemon {

/// Safety states. DISABLED -> ARMED -> RUNNING; any fault or stop goes through
/// RAMP_DOWN (output ramps to 0 V, then high voltage is disabled) to FAULT or
/// DISABLED. FAULT is left only by an explicit reset, to DISABLED (high voltage
/// off); arming again is a separate, explicit command.
enum class LoopState : std::uint8_t { disabled, armed, running, ramp_down, fault };
inline constexpr auto kLoopStateNames =
    enum_table<LoopState::disabled, LoopState::fault>({"DISABLED", "ARMED", "RUNNING", "RAMP_DOWN", "FAULT"});
constexpr const auto& names_of(LoopState) noexcept { return kLoopStateNames; }
constexpr std::string_view to_string(LoopState s) noexcept { return kLoopStateNames.to_string(s); }

/// Why the loop left RUNNING for FAULT. Carried in telemetry, recordings and logs.
enum class FaultReason : std::uint8_t {
  none,
  sensor_nan,             ///< the sensor returned NaN or inf
  sensor_out_of_range,    ///< outside [sensor_min_um, sensor_max_um]
  sensor_stale,           ///< the exact same reading for too many cycles
  sensor_timeout,         ///< too many consecutive reads without an answer
  amplifier_fault,        ///< the amplifier (or its interlock) reports a fault
  overrun_storm,          ///< too many consecutive missed deadlines
  setpoint_stale,         ///< the setpoint source ran dry (policy ramp_down)
  hal_error,              ///< another HAL failure on the sensor read (invalid reply, disconnected)
  actuator_write_failed,  ///< writing the amplifier command failed (timeouts in a row, invalid reply, link lost)
  hv_enable_failed,       ///< enabling high voltage failed (the arm is undone)
  hv_disable_failed,      ///< disabling high voltage reported a failure (retried every cycle)
};
inline constexpr auto kFaultReasonNames = enum_table<FaultReason::none, FaultReason::hv_disable_failed>(
    {"none", "sensor_nan", "sensor_out_of_range", "sensor_stale", "sensor_timeout", "amplifier_fault", "overrun_storm",
     "setpoint_stale", "hal_error", "actuator_write_failed", "hv_enable_failed", "hv_disable_failed"});
constexpr const auto& names_of(FaultReason) noexcept { return kFaultReasonNames; }
constexpr std::string_view to_string(FaultReason r) noexcept { return kFaultReasonNames.to_string(r); }

}  // namespace pvcgel::daemon
