#pragma once
// The register map of tests/hal/modbus_plant_server.py as a ModbusConfig
// (the same map as config/pvcgeld-modbus.toml).

#include "hal/modbus_backend.hpp"

namespace pvcgel::test {

inline hal::ModbusConfig plant_modbus_config(int port, double period_s = 0.020) {
  hal::ModbusConfig c;
  c.transport = hal::ModbusConfig::Transport::tcp;
  c.host = "127.0.0.1";
  c.port = port;
  c.unit_id = 1;
  c.period_s = period_s;
  c.io_budget_us = static_cast<int>(period_s * 1e6 * 0.6);
  c.response_timeout_us = c.io_budget_us / 2;
  c.startup_probe_cycles = 200;  // p99 tolerates two scheduling hiccups of a loaded 2-core machine
  c.reconnect_min_s = 0.02;
  c.reconnect_max_s = 0.2;
  c.sensor = {0, {32, true, hal::WordOrder::high_first}, {0.001, 0.0}};
  c.amplifier.address = 10;
  c.amplifier.format = {16, false, hal::WordOrder::high_first};
  c.amplifier.gain_V_per_V = 100.0;
  c.amplifier.input_map = {0.001, 0.0};
  c.amplifier.input_min_V = 0.0;
  c.amplifier.input_max_V = 10.0;
  c.monitor_voltage = hal::InputChannel{2, {16, false, hal::WordOrder::high_first}, {0.1, 0.0}};
  c.monitor_voltage_tolerance_V = 5.0;
  c.monitor_current = hal::InputChannel{3, {16, false, hal::WordOrder::high_first}, {0.001, 0.0}};
  c.monitor_current_max_mA = 1.0;
  return c;
}

/// The same map without the amplifier monitors, for test::RawModbusServer (whose
/// block would trip them: it is for protocol faults, not for the plant).
inline hal::ModbusConfig raw_server_modbus_config(int port) {
  hal::ModbusConfig c = plant_modbus_config(port);
  c.monitor_voltage.reset();
  c.monitor_current.reset();
  return c;
}

}  // namespace pvcgel::test
