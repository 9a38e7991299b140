#include "daemon/hal_factory.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "control/config_error.hpp"
#include "hal/gpiod_lines.hpp"
#include "hal/interlocked_hal.hpp"
#include "hal/modbus_backend.hpp"

namespace pvcgel::daemon {

namespace {

std::unique_ptr<hal::Hal> make_modbus(const DaemonConfig& cfg) {
  auto modbus = std::make_unique<hal::ModbusBackend>(cfg.hal.modbus);
  const auto& rtt = modbus->startup_rtt();
  std::fprintf(stderr,
               "pvcgeld: modbus %s: I/O per cycle p50 %.0f us, p99 %.0f us, max %.0f us over %d cycles "
               "(budget %d us, response timeout %d us)\n",
               modbus->describe_link().c_str(), rtt.p50_us, rtt.p99_us, rtt.max_us, rtt.cycles,
               cfg.hal.modbus.io_budget_us, cfg.hal.modbus.response_timeout_us);
  return modbus;
}

std::unique_ptr<hal::Hal> make_sim(const DaemonConfig& cfg, const std::optional<FaultInjection>& inject) {
  auto sim = std::make_unique<hal::SimBackend>(cfg.rig.sim);
  if (inject) sim->schedule(inject->fault, inject->at_s);
  return sim;
}

}  // namespace

FaultInjection parse_fault_injection(const std::string& spec) {
  const auto at = spec.find('@');
  const auto kind = parse_enum<hal::SimFault>(spec.substr(0, at));
  if (!kind || *kind == hal::SimFault::none || at == std::string::npos) {
    std::string kinds;
    for (const auto name : hal::kSimFaultNames.names())
      if (name != "none") kinds += (kinds.empty() ? "" : ", ") + std::string(name);
    throw control::ConfigError("--inject-fault", "expected KIND@SECONDS with KIND one of " + kinds + "; got '" + spec + "'");
  }
  const std::string when = spec.substr(at + 1);
  double t_s = NAN;
  const auto [end, ec] = std::from_chars(when.data(), when.data() + when.size(), t_s);
  if (ec != std::errc() || end != when.data() + when.size() || !(t_s >= 0.0))
    throw control::ConfigError("--inject-fault", "'" + when + "' is not a time in seconds (KIND@SECONDS)");
  return {*kind, t_s};
}

std::unique_ptr<hal::Hal> make_hal(const DaemonConfig& cfg, const std::optional<FaultInjection>& inject) {
  // The interlock lines first: HV enable is driven inactive before the amplifier link is touched.
  std::unique_ptr<hal::GpioLines> lines;
  if (cfg.hal.gpio) lines = std::make_unique<hal::GpiodLines>(*cfg.hal.gpio);
  std::unique_ptr<hal::Hal> backend;
  if (cfg.hal.backend == "modbus") {
    if (inject) throw control::ConfigError("--inject-fault", "faults can be injected only with [hal] backend = \"sim\"");
    backend = make_modbus(cfg);
  } else {
    backend = make_sim(cfg, inject);
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
