// Proves the modbus backend's real-time calls never allocate, against the real
// pymodbus server on loopback, on the good path and on the timeout, exception,
// garbage and disconnected paths. Global operator new is replaced by a counting one.
#include <gtest/gtest.h>

#include <thread>

#include "hal/modbus_backend.hpp"
#include "support/allocation_counter.hpp"
#include "support/modbus_peer.hpp"
#include "support/plant_modbus_config.hpp"
#include "support/raw_modbus_server.hpp"

using namespace pvcgel;
using namespace std::chrono_literals;

TEST(ModbusNoAllocation, CounterWorks) {
  const long before = g_allocations.load();
  std::vector<int> v;
  v.push_back(1);
  EXPECT_GT(g_allocations.load(), before) << "the counting operator new is not in effect";
}

TEST(ModbusNoAllocation, CyclesAgainstThePymodbusServerAllocateNothing) {
  test::PlantServer server({.slow_ms = 100.0});
  auto cfg = test::plant_modbus_config(server.port());
  cfg.reconnect_after_failures = 1000;
  hal::ModbusBackend backend(cfg);
  ASSERT_EQ(backend.set_high_voltage(true), hal::HalStatus::ok);
  double y = 0;
  const long before = g_allocations.load();
  for (int k = 0; k < 300; ++k) {
    ASSERT_EQ(backend.read_displacement(y), hal::HalStatus::ok);
    ASSERT_EQ(backend.write_voltage(2.0 * k), hal::HalStatus::ok);
  }
  backend.set_high_voltage(false);
  backend.set_high_voltage(true);
  const long good_path = g_allocations.load() - before;
  // Timeouts: the server stalls every read.
  server.toggle_slow();
  std::this_thread::sleep_for(50ms);
  int timeouts = 0;
  const long before_timeouts = g_allocations.load();
  for (int k = 0; k < 5; ++k) timeouts += backend.read_displacement(y) == hal::HalStatus::timeout;
  const long timeout_path = g_allocations.load() - before_timeouts;
  EXPECT_EQ(good_path, 0);
  EXPECT_EQ(timeout_path, 0);
  EXPECT_GE(timeouts, 3);
  EXPECT_GT(backend.health().reads, 300u);
}

TEST(ModbusNoAllocation, GarbageExceptionAndDisconnectedPathsAllocateNothing) {
  test::RawModbusServer raw;
  auto cfg = test::raw_server_modbus_config(raw.port());
  cfg.reconnect_after_failures = 8;
  cfg.reconnect_min_s = 5.0;  // stay down while we measure
  hal::ModbusBackend backend(cfg);
  double y = 0;
  raw.set_mode(test::RawModbusServer::Mode::garbage);
  const long before = g_allocations.load();
  for (int k = 0; k < 3; ++k) EXPECT_EQ(backend.read_displacement(y), hal::HalStatus::invalid_reply);
  raw.set_mode(test::RawModbusServer::Mode::exception);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(backend.write_voltage(1.0), hal::HalStatus::invalid_reply);
  for (int k = 0; k < 5; ++k) backend.read_displacement(y);
  EXPECT_FALSE(backend.link_up());
  EXPECT_EQ(backend.write_voltage(1.0), hal::HalStatus::disconnected);
  EXPECT_EQ(g_allocations.load() - before, 0);
}
