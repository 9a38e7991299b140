// [hal], [hal.modbus] and [hal.gpio] parsing: the shipped example, and key-named errors.
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

#include "control/config_error.hpp"
#include "daemon/daemon_config.hpp"

using namespace pvcgel;

namespace {

const std::string kExample = std::string(PVCGEL_SOURCE_DIR) + "/config/pvcgeld-modbus.toml";

std::string example_text() {
  std::ifstream f(kExample);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// The example with each `from` replaced by its `to`, loaded; returns the error key ("" if it loads).
std::string error_key_after(const std::vector<std::pair<std::string, std::string>>& edits, std::string* message = nullptr) {
  std::string text = example_text();
  for (const auto& [from, to] : edits) {
    const auto pos = text.find(from);
    if (pos == std::string::npos) throw std::runtime_error("example lacks '" + from + "'");
    text.replace(pos, from.size(), to);
  }
  const std::string path = ::testing::TempDir() + "hal_config_" + std::to_string(getpid()) + ".toml";
  std::ofstream(path) << text;
  try {
    daemon::load_daemon_config(path);
    return "";
  } catch (const control::ConfigError& e) {
    if (message) *message = e.what();
    return e.key();
  }
}

std::string error_key_after(const std::string& from, const std::string& to, std::string* message = nullptr) {
  return error_key_after({{from, to}}, message);
}

}  // namespace

TEST(HalConfig, ShippedModbusExampleParses) {
  const auto cfg = daemon::load_daemon_config(kExample);
  EXPECT_EQ(cfg.hal_backend, "modbus");
  const auto& m = cfg.hal.modbus;
  EXPECT_EQ(m.transport, hal::ModbusConfig::Transport::tcp);
  EXPECT_EQ(m.host, "192.168.10.20");
  EXPECT_EQ(m.port, 502);
  EXPECT_EQ(m.io_budget_us, 600);
  EXPECT_EQ(m.response_timeout_us, 300);
  EXPECT_DOUBLE_EQ(m.period_s, 0.001);
  EXPECT_EQ(m.sensor.format.width_bits, 32);
  EXPECT_TRUE(m.sensor.format.is_signed);
  EXPECT_DOUBLE_EQ(m.sensor.map.scale, 0.001);
  EXPECT_EQ(m.amplifier.address, 10);
  EXPECT_DOUBLE_EQ(m.amplifier.gain_V_per_V, 100.0);
  ASSERT_TRUE(m.monitor_voltage.has_value());
  EXPECT_EQ(m.monitor_voltage->address, 2);
  ASSERT_TRUE(m.monitor_current.has_value());
  EXPECT_DOUBLE_EQ(m.monitor_current_max_mA, 1.0);
  ASSERT_TRUE(cfg.hal.gpio.has_value());
  EXPECT_EQ(cfg.hal.gpio->hv_enable_line, "HV_EN");
  EXPECT_FALSE(cfg.hal.gpio->hv_enable_active_low);
  EXPECT_TRUE(cfg.hal.gpio->estop_active_low);
}

TEST(HalConfig, SimConfigsStillParseWithoutHalTables) {
  const auto cfg = daemon::load_daemon_config(std::string(PVCGEL_SOURCE_DIR) + "/config/pvcgeld-sim.toml");
  EXPECT_EQ(cfg.hal.backend, "sim");
  EXPECT_FALSE(cfg.hal.gpio.has_value());
}

TEST(HalConfig, ErrorsNameTheKey) {
  EXPECT_EQ(error_key_after("backend = \"modbus\"", "backend = \"canbus\""), "hal.backend");
  EXPECT_EQ(error_key_after("backend = \"modbus\"", "backend = \"sim\""), "hal.modbus");
  EXPECT_EQ(error_key_after("transport = \"tcp\"", "transport = \"udp\""), "hal.modbus.transport");
  EXPECT_EQ(error_key_after("transport = \"tcp\"", "transport = \"rtu\""), "hal.modbus.host");
  EXPECT_EQ(error_key_after("port = 502", "port = 70000"), "hal.modbus.port");
  EXPECT_EQ(error_key_after("unit_id = 1", "unit_id = 300"), "hal.modbus.unit_id");
  EXPECT_EQ(error_key_after("io_budget_us = 600", "io_budget_us = 950"), "hal.modbus.io_budget_us");
  EXPECT_EQ(error_key_after("response_timeout_us = 300", "response_timeout_us = 400"), "hal.modbus.response_timeout_us");
  EXPECT_EQ(error_key_after("width_bits = 32", "width_bits = 24"), "hal.modbus.sensor.width_bits");
  EXPECT_EQ(error_key_after("word_order = \"high_first\"", "word_order = \"big\""), "hal.modbus.sensor.word_order");
  EXPECT_EQ(error_key_after("um_per_count = 0.001", "um_per_count = 0.0"), "hal.modbus.sensor.um_per_count");
  EXPECT_EQ(error_key_after("um_per_count = 0.001", "um_per_cnt = 0.001"), "hal.modbus.sensor.um_per_count");
  EXPECT_EQ(error_key_after("register_type = \"input\"", "register_type = \"coil\""), "hal.modbus.sensor.register_type");
  EXPECT_EQ(error_key_after("address = 10", "address = 70000"), "hal.modbus.amplifier.address");
  EXPECT_EQ(error_key_after("gain_V_per_V = 100.0", "gain_V_per_V = -100.0"), "hal.modbus.amplifier.gain_V_per_V");
  EXPECT_EQ(error_key_after("input_min_V = 0.0", "input_min_V = 1.0"), "hal.modbus.amplifier.input_min_V");
  EXPECT_EQ(error_key_after("tolerance_V = 20.0", "tolerance_V = 0.0"), "hal.modbus.monitor_voltage.tolerance_V");
  EXPECT_EQ(error_key_after("max_mA = 1.0", "max_mA = 1.0\nmax_ma = 2.0"), "hal.modbus.monitor_current.max_ma");
  EXPECT_EQ(error_key_after("estop_line = \"ESTOP\"", "estop_line = \"\""), "hal.gpio.estop_line");
  EXPECT_EQ(error_key_after("chip = \"gpiochip0\"", "chip = 0"), "hal.gpio.chip");
  std::string msg;
  EXPECT_EQ(error_key_after("io_budget_us = 600", "io_budget_us = 2000", &msg), "hal.modbus.io_budget_us");
  EXPECT_NE(msg.find("900 us"), std::string::npos) << msg;
  EXPECT_NE(msg.find(".toml)"), std::string::npos) << "the message names the file: " << msg;
}

TEST(HalConfig, RtuNeedsADeviceAndRejectsTcpKeys) {
  const std::pair<std::string, std::string> rtu{"transport = \"tcp\"", "transport = \"rtu\"\nbaud = 921600"};
  const std::pair<std::string, std::string> no_host{"host = \"192.168.10.20\"", ""}, no_port{"port = 502", ""};
  const std::pair<std::string, std::string> device{"unit_id = 1", "unit_id = 1\ndevice = \"/dev/ttyUSB0\""};
  EXPECT_EQ(error_key_after({rtu, no_host, no_port, device}), "");
  EXPECT_EQ(error_key_after({rtu, no_host, no_port}), "hal.modbus.device");
  EXPECT_EQ(error_key_after({rtu, no_host, device}), "hal.modbus.port");
  EXPECT_EQ(error_key_after({rtu, no_host, no_port, device, {"baud = 921600", "baud = 921600\nparity = \"X\""}}),
            "hal.modbus.parity");
}
