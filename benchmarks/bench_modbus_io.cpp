// HAL I/O time per cycle (read sensor + write amplifier) of the modbus backend
// against the pymodbus plant server on loopback, beside a raw libmodbus client
// doing the same two transactions (read 4 input registers, write 1 holding
// register) on its own connection to the same server, in the same run,
// alternating cycle by cycle. Target: backend overhead <= 10% over raw.
// Usage: bench_modbus_io [cycles=3000]
#include <modbus/modbus.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>
#include <vector>

#include "hal/modbus_backend.hpp"
#include "support/modbus_peer.hpp"
#include "support/plant_modbus_config.hpp"

using namespace pvcgel;
using Clock = std::chrono::steady_clock;

namespace {

struct Quantiles {
  double p50, p99, p999;
};

Quantiles quantiles(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const auto q = [&](double p) { return v[std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size())))]; };
  return {q(0.5), q(0.99), q(0.999)};
}

}  // namespace

int main(int argc, char** argv) {
  const int cycles = argc > 1 ? std::atoi(argv[1]) : 3000;
  test::PlantServer server({});
  // A generous deadline: this measures time per cycle, not whether it fits a budget.
  auto cfg = test::plant_modbus_config(server.port(), 0.2);
  cfg.reconnect_after_failures = 1000000;
  hal::ModbusBackend backend(cfg);
  backend.set_high_voltage(true);

  modbus_t* raw = modbus_new_tcp("127.0.0.1", server.port());
  modbus_set_slave(raw, 1);
  modbus_set_response_timeout(raw, 0, static_cast<std::uint32_t>(cfg.response_timeout_us));
  modbus_set_byte_timeout(raw, 0, 0);
  if (modbus_connect(raw) != 0) {
    std::fprintf(stderr, "raw client cannot connect: %s\n", modbus_strerror(errno));
    return 1;
  }

  std::vector<double> hal_us, raw_us;
  hal_us.reserve(static_cast<size_t>(cycles));
  raw_us.reserve(static_cast<size_t>(cycles));
  long hal_errors = 0, raw_errors = 0;
  std::uint16_t regs[4];
  for (int k = 0; k < cycles + 50; ++k) {
    const double u = 100.0 + 50.0 * (k % 7);
    const auto counts = static_cast<std::uint16_t>(u * 10.0);
    // Alternate which goes first so neither always follows a sleep.
    for (int which = 0; which < 2; ++which) {
      const bool do_hal = (which == 0) == (k % 2 == 0);
      const auto t0 = Clock::now();
      bool ok;
      if (do_hal) {
        double y = 0;
        ok = backend.read_displacement(y) == hal::HalStatus::ok;
        ok = backend.write_voltage(u) == hal::HalStatus::ok && ok;
      } else {
        ok = modbus_read_input_registers(raw, 0, 4, regs) == 4;
        ok = modbus_write_register(raw, 10, counts) == 1 && ok;
      }
      const double us = std::chrono::duration<double, std::micro>(Clock::now() - t0).count();
      if (k < 50) continue;  // warm-up
      if (!ok) ++(do_hal ? hal_errors : raw_errors);
      (do_hal ? hal_us : raw_us).push_back(us);
    }
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  modbus_close(raw);
  modbus_free(raw);

  const auto h = quantiles(hal_us), r = quantiles(raw_us);
  std::printf("Modbus TCP loopback against pymodbus 3.0, one cycle = read 4 input registers + write 1 register, %d cycles\n",
              cycles);
  std::printf("  start-up RTT (backend)     p50 %7.0f us  p99 %7.0f us\n", backend.startup_rtt().p50_us,
              backend.startup_rtt().p99_us);
  std::printf("  raw libmodbus client       p50 %7.1f us  p99 %7.1f us  p99.9 %7.1f us  errors %ld\n", r.p50, r.p99, r.p999,
              raw_errors);
  std::printf("  modbus HAL backend         p50 %7.1f us  p99 %7.1f us  p99.9 %7.1f us  errors %ld\n", h.p50, h.p99, h.p999,
              hal_errors);
  std::printf("  overhead backend/raw       p50 %+6.1f %%     p99 %+6.1f %%   (target <= +10 %%)\n",
              (h.p50 / r.p50 - 1.0) * 100.0, (h.p99 / r.p99 - 1.0) * 100.0);
  const auto health = backend.health();
  std::printf("  backend counters: %llu timeouts, %llu exceptions, %llu garbage\n",
              static_cast<unsigned long long>(health.timeouts), static_cast<unsigned long long>(health.exceptions),
              static_cast<unsigned long long>(health.garbage_frames));
  return 0;
}
