#pragma once
/// @file
/// The interlock's GPIO lines as one small interface: the high-voltage enable
/// output and the emergency-stop and amplifier-fault inputs.

#include <string>

namespace pvcgel::hal {

/// Chip and lines of the interlock, validated by the config parser.
struct GpioConfig {
  std::string chip;                  ///< chip name ("gpiochip0"), path or label
  std::string hv_enable_line;        ///< line name (or decimal offset) of the HV-enable output
  bool hv_enable_active_low = false; ///< true: the amplifier is enabled by a low level
  std::string estop_line;            ///< line name (or offset) of the emergency-stop input
  bool estop_active_low = true;      ///< true: e-stop pressed pulls the line low (NC contact to ground)
  std::string amp_fault_line;        ///< line name (or offset) of the amplifier-fault input; empty: none
  bool amp_fault_active_low = true;
};

/// What the inputs said since the last poll.
struct InterlockInputs {
  bool estop_active = false;      ///< e-stop level now (logical: true = pressed)
  bool amp_fault_active = false;  ///< amplifier-fault level now (logical: true = fault)
  bool edge_seen = false;         ///< at least one edge on either input since the last poll
  bool ok = true;                 ///< false when the lines could not be read
};

/// The lines, as the interlock sees them. Every call is noexcept, non-blocking
/// and allocation-free (called from the real-time thread).
class GpioLines {
 public:
  virtual ~GpioLines() = default;
  GpioLines() = default;
  GpioLines(const GpioLines&) = delete;
  GpioLines& operator=(const GpioLines&) = delete;

  /// Drive the HV-enable output (logical level; the active level is the implementation's). @return false on failure.
  virtual bool set_enable(bool enabled) noexcept = 0;
  /// Drain pending edge events and read the input levels, without waiting.
  virtual InterlockInputs poll() noexcept = 0;
};

}  // namespace pvcgel::hal
