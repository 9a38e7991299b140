#pragma once
/// @file
/// The `[hal]` table of pvcgeld's configuration: backend choice, `[hal.modbus]`
/// (link and register map) and the optional `[hal.gpio]` interlock.

#include <optional>
#include <string>

#include "control/config/toml_reader.hpp"
#include "hal/gpio_lines.hpp"
#include "hal/modbus_backend.hpp"

namespace pvcgel::daemon {

/// `[hal]`, validated.
struct HalConfig {
  std::string backend = "sim";           ///< "sim" or "modbus"
  hal::ModbusConfig modbus;              ///< `[hal.modbus]` (backend "modbus")
  std::optional<hal::GpioConfig> gpio;   ///< `[hal.gpio]`, when present: the HV interlock
};

/// Reads `[hal]` (the reader of that table; finish() is called here). `period_s`
/// is the loop period the Modbus link must keep up with.
/// @throws control::ConfigError naming the key.
HalConfig parse_hal_config(control::TableReader& hal, double period_s);

}  // namespace pvcgel::daemon
