#pragma once
/// @file
/// Builds the configured HAL: the sim backend or the Modbus backend, either
/// wrapped in the GPIO interlock when `[hal.gpio]` is present.

#include <memory>
#include <optional>
#include <string>

#include "daemon/daemon_config.hpp"
#include "hal/hal.hpp"
#include "hal/sim_backend.hpp"

namespace pvcgel::daemon {

/// A fault the sim backend injects when simulated time reaches `at_s`
/// (`pvcgeld --inject-fault KIND@SECONDS`).
struct FaultInjection {
  hal::SimFault fault = hal::SimFault::none;
  double at_s = 0.0;
};

/// Parses `KIND@SECONDS`, e.g. "sensor_nan@3".
/// @throws control::ConfigError naming --inject-fault, the kinds and what was given.
FaultInjection parse_fault_injection(const std::string& spec);

/// The HAL for `cfg.hal`: the simulated rig (with `inject` scheduled) for
/// backend "sim", else the Modbus backend (no simulated rig is built; an
/// injection is then a configuration error). Connecting to a real backend
/// happens here (and is logged to stderr with the measured round trip).
/// @throws control::ConfigError, std::runtime_error (see ModbusBackend, GpiodLines).
std::unique_ptr<hal::Hal> make_hal(const DaemonConfig& cfg, const std::optional<FaultInjection>& inject);

/// One line for logs and status: "link up, 3 timeouts, 0 exceptions, 1 garbage, 0 reconnects".
std::string health_summary(const hal::HalHealth& h);

}  // namespace pvcgel::daemon
