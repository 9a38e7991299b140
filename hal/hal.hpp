#pragma once
/// @file
/// The hardware abstraction: one small interface for the rig's I/O.

#include <cstdint>
#include <string_view>

#include "control/enum_table.hpp"

namespace pvcgel::hal {

/// Result of one HAL operation. Returned, never thrown: the loop must not unwind.
enum class HalStatus : std::uint8_t {
  ok,
  timeout,         ///< no answer within the cycle's I/O budget
  invalid_reply,   ///< an answer that cannot be a measurement (garbage, out of range)
  device_fault,    ///< the device reports a fault (amplifier fault, emergency stop)
  disconnected,    ///< link down; reconnection happens off the real-time thread
};

inline constexpr auto kHalStatusNames = enum_table<HalStatus::ok, HalStatus::disconnected>(
    {"ok", "timeout", "invalid_reply", "device_fault", "disconnected"});
constexpr const auto& names_of(HalStatus) noexcept { return kHalStatusNames; }
/// Name of a status (for logs and tests).
constexpr std::string_view to_string(HalStatus s) noexcept { return kHalStatusNames.to_string(s); }

/// Counters a backend keeps for status reports (read from non-RT threads).
struct HalHealth {
  std::uint64_t reads = 0, writes = 0, timeouts = 0, invalid_replies = 0, device_faults = 0;
  std::uint64_t exceptions = 0;      ///< protocol exception replies (counted in invalid_replies too)
  std::uint64_t garbage_frames = 0;  ///< malformed replies (counted in invalid_replies too)
  std::uint64_t reconnects = 0;      ///< links re-established after a loss
  bool link_up = true;               ///< false while a backend reconnects
  bool high_voltage_enabled = false;
  bool amplifier_fault = false;
};

/// The rig as the control loop sees it. Every call made from the real-time
/// thread (read_displacement, write_voltage, set_high_voltage) is noexcept,
/// allocation-free and bounded in time. Lifecycle: construct (may throw with a
/// configuration message), then the loop calls these, then destroy (which
/// must leave the amplifier at 0 V with high voltage disabled).
class Hal {
 public:
  virtual ~Hal() = default;
  Hal() = default;
  Hal(const Hal&) = delete;
  Hal& operator=(const Hal&) = delete;

  /// Laser displacement sensor reading at the start of this cycle, in um.
  virtual HalStatus read_displacement(double& y_um) noexcept = 0;
  /// Amplifier command for this cycle, held until the next (V, already clamped).
  virtual HalStatus write_voltage(double voltage_V) noexcept = 0;
  /// High-voltage enable (the interlock). Disabling must work even when writes fail.
  virtual HalStatus set_high_voltage(bool enabled) noexcept = 0;
  /// Snapshot of the counters.
  [[nodiscard]] virtual HalHealth health() const noexcept = 0;
  /// Backend name for logs and status ("sim", "modbus", ...).
  [[nodiscard]] virtual std::string_view name() const noexcept = 0;
};

}  // namespace pvcgel::hal
