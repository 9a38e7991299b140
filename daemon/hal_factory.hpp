#pragma once
/// @file
/// Builds the configured HAL: the sim backend or the Modbus backend, either
/// wrapped in the GPIO interlock when `[hal.gpio]` is present.

#include <memory>
#include <string>

#include "daemon/daemon_config.hpp"
#include "hal/hal.hpp"
#include "hal/sim_backend.hpp"

namespace pvcgel::daemon {

/// The HAL for `cfg.hal`. `sim` is used for backend "sim" (it may carry
/// scheduled faults); `faults_injected` says whether it does, which is an error
/// with another backend. Connecting to a real backend happens here (and is
/// logged to stderr with the measured round trip).
/// @throws control::ConfigError, std::runtime_error (see ModbusBackend, GpiodLines).
std::unique_ptr<hal::Hal> make_hal(const DaemonConfig& cfg, std::unique_ptr<hal::SimBackend> sim, bool faults_injected);

/// One line for logs and status: "link up, 3 timeouts, 0 exceptions, 1 garbage, 0 reconnects".
std::string health_summary(const hal::HalHealth& h);

}  // namespace pvcgel::daemon
