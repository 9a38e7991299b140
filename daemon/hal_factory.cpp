#include "daemon/hal_factory.hpp"

#include <cstdio>
#include <iostream>

#include "control/config_error.hpp"
#include "hal/gpiod_lines.hpp"
#include "hal/interlocked_hal.hpp"
#include "hal/modbus_backend.hpp"

namespace pvcgel::daemon {

std::unique_ptr<hal::Hal> make_hal(const DaemonConfig& cfg, std::unique_ptr<hal::SimBackend> sim, bool faults_injected) {
  // The interlock lines first: HV enable is driven inactive before the amplifier link is touched.
  std::unique_ptr<hal::GpioLines> lines;
  if (cfg.hal.gpio) lines = std::make_unique<hal::GpiodLines>(*cfg.hal.gpio);
  std::unique_ptr<hal::Hal> backend;
  if (cfg.hal.backend == "modbus") {
    if (faults_injected)
      throw control::ConfigError("--inject-fault", "faults can be injected only with [hal] backend = \"sim\"");
    auto modbus = std::make_unique<hal::ModbusBackend>(cfg.hal.modbus);
    const auto& rtt = modbus->startup_rtt();
    std::fprintf(stderr,
                 "pvcgeld: modbus %s: I/O per cycle p50 %.0f us, p99 %.0f us, max %.0f us over %d cycles "
                 "(budget %d us, response timeout %d us)\n",
                 modbus->describe_link().c_str(), rtt.p50_us, rtt.p99_us, rtt.max_us, rtt.cycles,
                 cfg.hal.modbus.io_budget_us, cfg.hal.modbus.response_timeout_us);
    backend = std::move(modbus);
  } else {
    backend = std::move(sim);
  }
  if (!lines) return backend;
  return std::make_unique<hal::InterlockedHal>(std::move(backend), std::move(lines), cfg.safety.sensor_timeout_cycles);
}

std::string health_summary(const hal::HalHealth& h) {
  char buf[200];
  std::snprintf(buf, sizeof buf, "link %s, %llu timeouts, %llu exceptions, %llu garbage, %llu reconnects",
                h.link_up ? "up" : "DOWN", static_cast<unsigned long long>(h.timeouts),
                static_cast<unsigned long long>(h.exceptions), static_cast<unsigned long long>(h.garbage_frames),
                static_cast<unsigned long long>(h.reconnects));
  return buf;
}

}  // namespace pvcgel::daemon
