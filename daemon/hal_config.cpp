#include "daemon/hal_config.hpp"

#include <cmath>

namespace pvcgel::daemon {

using control::ConfigError;
using control::TableReader;

namespace {

std::uint16_t register_address(TableReader& t, const std::string& k, int fallback) {
  const int a = t.integer(k, fallback);
  if (a < 0 || a > 65535) throw ConfigError(t.key(k), "must be a register address 0..65535 (zero-based, as on the wire)");
  return static_cast<std::uint16_t>(a);
}

hal::RegisterFormat register_format(TableReader& t, const hal::RegisterFormat& fallback) {
  hal::RegisterFormat f = fallback;
  const int width = t.integer("width_bits", f.width_bits);
  if (width != 16 && width != 32) throw ConfigError(t.key("width_bits"), "must be 16 or 32");
  f.width_bits = static_cast<std::uint8_t>(width);
  f.is_signed = t.boolean("signed", f.is_signed);
  const std::string order = t.string("word_order", std::string(to_string(f.word_order)));
  const auto wo = parse_enum<hal::WordOrder>(order);
  if (!wo) throw ConfigError(t.key("word_order"), "must be \"high_first\" or \"low_first\" (got '" + order + "')");
  f.word_order = *wo;
  return f;
}

double nonzero(TableReader& t, const std::string& k, double fallback) {
  const double v = t.number(k, fallback);
  if (v == 0.0) throw ConfigError(t.key(k), "must not be 0");
  return v;
}

hal::InputChannel input_channel(TableReader& t, const hal::InputChannel& fallback, const std::string& per_count,
                                const std::string& offset) {
  hal::InputChannel ch = fallback;
  ch.address = register_address(t, "address", ch.address);
  ch.format = register_format(t, ch.format);
  ch.map.scale = nonzero(t, per_count, ch.map.scale);
  ch.map.offset = t.number(offset, ch.map.offset);
  return ch;
}

/// Transport, address and serial line settings, and the unit id.
void parse_link(TableReader& m, hal::ModbusConfig& c) {
  const std::string transport = m.string("transport", "tcp");
  const auto parsed = parse_enum<hal::ModbusConfig::Transport>(transport);
  if (parsed) c.transport = *parsed;
  else throw ConfigError(m.key("transport"), "must be \"tcp\" or \"rtu\" (got '" + transport + "')");
  const bool tcp = c.transport == hal::ModbusConfig::Transport::tcp;
  const auto only_for = [&](const std::string& k, bool allowed, const char* what) {
    if (m.has(k) && !allowed) throw ConfigError(m.key(k), std::string("only applies to transport = \"") + what + "\"");
  };
  for (const char* k : {"host", "port"}) only_for(k, tcp, "tcp");
  for (const char* k : {"device", "baud", "parity", "data_bits", "stop_bits"}) only_for(k, !tcp, "rtu");

  c.host = m.string("host", c.host);
  if (tcp && c.host.empty()) throw ConfigError(m.key("host"), "must name the module's address");
  c.port = m.integer("port", c.port);
  if (c.port < 1 || c.port > 65535) throw ConfigError(m.key("port"), "must be 1..65535");
  c.device = m.string("device", "");
  if (!tcp && c.device.empty()) throw ConfigError(m.key("device"), "is required for transport = \"rtu\" (e.g. \"/dev/ttyUSB0\")");
  c.baud = m.integer("baud", c.baud);
  if (c.baud < 300 || c.baud > 4000000) throw ConfigError(m.key("baud"), "must be 300..4000000");
  const std::string parity = m.string("parity", "N");
  if (parity != "N" && parity != "E" && parity != "O") throw ConfigError(m.key("parity"), "must be \"N\", \"E\" or \"O\"");
  c.parity = parity[0];
  c.data_bits = m.integer("data_bits", c.data_bits);
  if (c.data_bits < 5 || c.data_bits > 8) throw ConfigError(m.key("data_bits"), "must be 5..8");
  c.stop_bits = m.integer("stop_bits", c.stop_bits);
  if (c.stop_bits != 1 && c.stop_bits != 2) throw ConfigError(m.key("stop_bits"), "must be 1 or 2");
  c.unit_id = m.integer("unit_id", c.unit_id);
  if (c.unit_id < (tcp ? 0 : 1) || c.unit_id > (tcp ? 255 : 247))
    throw ConfigError(m.key("unit_id"), tcp ? "must be 0..255" : "must be 1..247 on a serial line");
}

/// The I/O budget per cycle, the response timeout, and reconnection.
void parse_timing(TableReader& m, double period_s, hal::ModbusConfig& c) {
  const int period_us = static_cast<int>(std::lround(period_s * 1e6));
  c.io_budget_us = m.integer("io_budget_us", std::max(1, period_us / 2));
  if (c.io_budget_us < 1 || c.io_budget_us > period_us * 9 / 10)
    throw ConfigError(m.key("io_budget_us"), "must be 1..90% of the loop period (" + std::to_string(period_us * 9 / 10) +
                                                 " us at [controller] period_s = " + std::to_string(period_s) + ")");
  c.response_timeout_us = m.integer("response_timeout_us", c.io_budget_us / 2);
  if (c.response_timeout_us < 1 || 2 * c.response_timeout_us > c.io_budget_us)
    throw ConfigError(m.key("response_timeout_us"), "must be positive and at most half of io_budget_us (" +
                                                        std::to_string(c.io_budget_us) + " us): two transactions per cycle");
  c.startup_probe_cycles = m.integer("startup_probe_cycles", c.startup_probe_cycles);
  if (c.startup_probe_cycles < 10) throw ConfigError(m.key("startup_probe_cycles"), "must be >= 10");
  c.reconnect_after_failures = m.integer("reconnect_after_failures", c.reconnect_after_failures);
  if (c.reconnect_after_failures < 1) throw ConfigError(m.key("reconnect_after_failures"), "must be >= 1");
  c.reconnect_min_s = m.number("reconnect_min_s", c.reconnect_min_s);
  if (!(c.reconnect_min_s > 0.0)) throw ConfigError(m.key("reconnect_min_s"), "must be positive");
  c.reconnect_max_s = m.number("reconnect_max_s", c.reconnect_max_s);
  if (!(c.reconnect_max_s >= c.reconnect_min_s)) throw ConfigError(m.key("reconnect_max_s"), "must be >= reconnect_min_s");
}

void parse_sensor(TableReader& m, hal::ModbusConfig& c) {
  auto s = m.table("sensor");
  if (!s.present()) throw ConfigError(m.key("sensor"), "is required: the displacement sensor's register");
  const std::string fc = s.string("register_type", "input");
  if (fc != "input" && fc != "holding") throw ConfigError(s.key("register_type"), "must be \"input\" or \"holding\"");
  c.sensor_in_holding = fc == "holding";
  if (!s.has("um_per_count")) throw ConfigError(s.key("um_per_count"), "is required (micrometres per count)");
  c.sensor = input_channel(s, c.sensor, "um_per_count", "offset_um");
  s.finish();
}

void parse_amplifier(TableReader& m, hal::ModbusConfig& c) {
  auto a = m.table("amplifier");
  if (!a.present()) throw ConfigError(m.key("amplifier"), "is required: the amplifier's control register");
  auto& amp = c.amplifier;
  amp.address = register_address(a, "address", amp.address);
  amp.format = register_format(a, {16, false, hal::WordOrder::high_first});
  amp.gain_V_per_V = a.number("gain_V_per_V", amp.gain_V_per_V);
  if (!(amp.gain_V_per_V > 0.0)) throw ConfigError(a.key("gain_V_per_V"), "must be positive (the amplifier's fixed gain)");
  amp.input_map.scale = nonzero(a, "input_V_per_count", amp.input_map.scale);
  amp.input_map.offset = a.number("input_offset_V", amp.input_map.offset);
  amp.input_min_V = a.number("input_min_V", amp.input_min_V);
  amp.input_max_V = a.number("input_max_V", amp.input_max_V);
  if (!(amp.input_max_V > amp.input_min_V)) throw ConfigError(a.key("input_max_V"), "must be above input_min_V");
  if (!(amp.input_min_V <= 0.0)) throw ConfigError(a.key("input_min_V"), "must allow 0 V (the safe state)");
  std::int64_t zero = 0;
  if (!amp.output_to_counts(0.0, zero))
    throw ConfigError(a.key("input_offset_V"), "0 V cannot be represented in the amplifier register");
  a.finish();
}

/// The optional monitors of the amplifier's output voltage and current.
void parse_monitors(TableReader& m, hal::ModbusConfig& c) {
  if (auto mv = m.table("monitor_voltage"); mv.present()) {
    if (!mv.has("address")) throw ConfigError(mv.key("address"), "is required");
    c.monitor_voltage = input_channel(mv, {c.sensor.address, {16, false, hal::WordOrder::high_first}, {1.0, 0.0}},
                                      "V_per_count", "offset_V");
    c.monitor_voltage_tolerance_V = mv.number("tolerance_V", c.monitor_voltage_tolerance_V);
    if (!(c.monitor_voltage_tolerance_V > 0.0)) throw ConfigError(mv.key("tolerance_V"), "must be positive");
    c.monitor_fault_after_cycles = mv.integer("fault_after_cycles", c.monitor_fault_after_cycles);
    if (c.monitor_fault_after_cycles < 1) throw ConfigError(mv.key("fault_after_cycles"), "must be >= 1");
    mv.finish();
  }
  if (auto mc = m.table("monitor_current"); mc.present()) {
    if (!mc.has("address")) throw ConfigError(mc.key("address"), "is required");
    c.monitor_current = input_channel(mc, {c.sensor.address, {16, false, hal::WordOrder::high_first}, {1.0, 0.0}},
                                      "mA_per_count", "offset_mA");
    c.monitor_current_max_mA = mc.number("max_mA", c.monitor_current_max_mA);
    if (!(c.monitor_current_max_mA > 0.0)) throw ConfigError(mc.key("max_mA"), "must be positive");
    mc.finish();
  }
}

void parse_modbus(TableReader& m, double period_s, hal::ModbusConfig& c) {
  c.period_s = period_s;
  parse_link(m, c);
  parse_timing(m, period_s, c);
  parse_sensor(m, c);
  parse_amplifier(m, c);
  parse_monitors(m, c);
  m.finish();
}

hal::GpioConfig parse_gpio(TableReader& g) {
  hal::GpioConfig c;
  const auto required = [&](const std::string& k) {
    std::string v = g.string(k, "");
    if (v.empty()) throw ConfigError(g.key(k), "is required (a line name as gpioinfo shows it, or an offset)");
    return v;
  };
  c.chip = required("chip");
  c.hv_enable_line = required("hv_enable_line");
  c.hv_enable_active_low = g.boolean("hv_enable_active_low", c.hv_enable_active_low);
  c.estop_line = required("estop_line");
  c.estop_active_low = g.boolean("estop_active_low", c.estop_active_low);
  c.amp_fault_line = g.string("amp_fault_line", "");
  c.amp_fault_active_low = g.boolean("amp_fault_active_low", c.amp_fault_active_low);
  g.finish();
  return c;
}

}  // namespace

HalConfig parse_hal_config(TableReader& hal, double period_s) {
  HalConfig cfg;
  cfg.backend = hal.string("backend", cfg.backend);
  if (cfg.backend != "sim" && cfg.backend != "modbus")
    throw ConfigError(hal.key("backend"), "must be \"sim\" or \"modbus\" (got '" + cfg.backend + "')");
  auto m = hal.table("modbus");
  if (cfg.backend == "modbus") {
    if (!m.present()) throw ConfigError(hal.key("modbus"), "is required for backend = \"modbus\"");
    parse_modbus(m, period_s, cfg.modbus);
  } else if (m.present()) {
    throw ConfigError(hal.key("modbus"), "given but backend is \"" + cfg.backend + "\"; set backend = \"modbus\" or remove it");
  }
  if (auto g = hal.table("gpio"); g.present()) cfg.gpio = parse_gpio(g);
  hal.finish();
  return cfg;
}

}  // namespace pvcgel::daemon
