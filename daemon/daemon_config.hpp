#pragma once
/// @file
/// pvcgeld's configuration file: the control tables plus [loop], [hal], [safety], [run], [dds], [setpoints].

#include <limits>
#include <string>

#include "control/config/config_parser.hpp"
#include "daemon/control_loop.hpp"
#include "daemon/dds/dds_participant.hpp"
#include "daemon/hal_config.hpp"
#include "daemon/realtime_thread.hpp"

namespace pvcgel::daemon {

/// Everything pvcgeld reads from its TOML file, validated.
struct DaemonConfig {
  control::RigConfiguration rig;
  RealtimeConfig realtime;
  SafetyConfig safety;
  std::string hal_backend = "sim";
  HalConfig hal;  ///< `[hal]`: backend, `[hal.modbus]`, `[hal.gpio]`
  std::string trajectory;  ///< empty: idle DISABLED until a setpoint source starts the loop
  double duration_s = std::numeric_limits<double>::infinity();
  std::string config_hash;  ///< FNV-1a 64 of the file's bytes, hex
  bool dds_enabled = false;  ///< publish Telemetry over DDS
  dds::DdsSettings dds;      ///< `[dds]`; config path resolved relative to the config file
  SetpointLimits setpoint_limits;  ///< `[setpoints]`: checks on setpoints and commands received over DDS
};

/// Reads and validates `path`. @throws control::ConfigError naming the key and
/// file (key "--config" when the file cannot be read or is not valid TOML).
DaemonConfig load_daemon_config(const std::string& path);

}  // namespace pvcgel::daemon
