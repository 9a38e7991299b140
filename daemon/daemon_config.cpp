#include "daemon/daemon_config.hpp"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "control/toml_reader.hpp"

namespace pvcgel::daemon {

using control::ConfigError;

DaemonConfig load_daemon_config(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  // Unreadable or unparsable files are configuration errors too (exit 2: systemd must not restart).
  if (!in) throw ConfigError("--config", "cannot read configuration file '" + path + "'");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();

  toml::table root;
  try {
    root = toml::parse(text, path);
  } catch (const toml::parse_error& e) {
    std::ostringstream os;
    os << path << ":" << e.source().begin.line << ":" << e.source().begin.column << ": " << e.description();
    throw ConfigError("--config", os.str());
  }

  DaemonConfig cfg;
  cfg.rig = control::parse_configuration(root, path, {"loop", "hal", "safety", "run", "dds", "setpoints"});
  cfg.realtime.period_s = cfg.rig.controller.sample_time_s;

  control::with_source(path, [&] {
    control::TableReader top(&root, "");
    auto loop = top.table("loop");
    cfg.realtime.priority = loop.integer("priority", cfg.realtime.priority);
    if (cfg.realtime.priority < 1 || cfg.realtime.priority > 99) throw ConfigError(loop.key("priority"), "must be 1..99");
    cfg.realtime.cpu = loop.integer("cpu", cfg.realtime.cpu);
    if (cfg.realtime.cpu < -1 || cfg.realtime.cpu > 1023) throw ConfigError(loop.key("cpu"), "must be -1 (no affinity) or a CPU number");
    cfg.realtime.lock_memory = loop.boolean("lock_memory", cfg.realtime.lock_memory);
    cfg.realtime.cpu_dma_latency_us = loop.integer("cpu_dma_latency_us", cfg.realtime.cpu_dma_latency_us);
    cfg.safety.overrun_fault_after = loop.integer("overrun_fault_after", cfg.safety.overrun_fault_after);
    if (cfg.safety.overrun_fault_after < 0) throw ConfigError(loop.key("overrun_fault_after"), "must be >= 0 (0: never fault)");
    loop.finish();

    auto hal = top.table("hal");
    cfg.hal = parse_hal_config(hal, cfg.realtime.period_s);
    cfg.hal_backend = cfg.hal.backend;

    auto s = top.table("safety");
    auto& sc = cfg.safety;
    sc.ramp_down_V_per_s = s.number("ramp_down_V_per_s", sc.ramp_down_V_per_s);
    if (!(sc.ramp_down_V_per_s > 0.0)) throw ConfigError(s.key("ramp_down_V_per_s"), "must be positive");
    sc.sensor_min_um = s.number("sensor_min_um", sc.sensor_min_um);
    sc.sensor_max_um = s.number("sensor_max_um", sc.sensor_max_um);
    if (!(sc.sensor_max_um > sc.sensor_min_um)) throw ConfigError(s.key("sensor_max_um"), "must be above sensor_min_um");
    sc.sensor_stale_cycles = s.integer("sensor_stale_cycles", sc.sensor_stale_cycles);
    if (sc.sensor_stale_cycles < 0) throw ConfigError(s.key("sensor_stale_cycles"), "must be >= 0 (0: off)");
    sc.sensor_timeout_cycles = s.integer("sensor_timeout_cycles", sc.sensor_timeout_cycles);
    if (sc.sensor_timeout_cycles < 1) throw ConfigError(s.key("sensor_timeout_cycles"), "must be >= 1");
    const auto policy = s.string("stale_setpoint", "hold");
    if (policy == "hold") sc.stale_setpoint = StaleSetpointPolicy::hold;
    else if (policy == "ramp_down") sc.stale_setpoint = StaleSetpointPolicy::ramp_down;
    else throw ConfigError(s.key("stale_setpoint"), "must be \"hold\" or \"ramp_down\"");
    sc.soft_start_s = s.number("soft_start_s", sc.soft_start_s);
    if (!(sc.soft_start_s >= 0.0)) throw ConfigError(s.key("soft_start_s"), "must be >= 0");
    sc.open_loop_slew_V_per_s = s.number("open_loop_slew_V_per_s", sc.open_loop_slew_V_per_s);
    if (!(sc.open_loop_slew_V_per_s > 0.0)) throw ConfigError(s.key("open_loop_slew_V_per_s"), "must be positive");
    s.finish();

    auto run = top.table("run");
    cfg.trajectory = run.string("trajectory", "");
    cfg.duration_s = run.number("duration_s", cfg.duration_s);
    if (!(cfg.duration_s > 0.0)) throw ConfigError(run.key("duration_s"), "must be positive");
    run.finish();

    auto d = top.table("dds");
    cfg.dds_enabled = d.boolean("enabled", false);
    cfg.dds.domain = d.integer("domain", 0);
    if (cfg.dds.domain < 0 || cfg.dds.domain > 232) throw ConfigError(d.key("domain"), "must be 0..232");
    cfg.dds.rig_id = d.string("rig_id", cfg.dds.rig_id);
    if (cfg.dds.rig_id.empty() || cfg.dds.rig_id.size() > 32)
      throw ConfigError(d.key("rig_id"), "must be 1..32 characters");
    cfg.dds.reliable_telemetry = d.boolean("reliable_telemetry", false);
    cfg.dds.realtime_priority = d.integer("realtime_priority", 0);
    if (cfg.dds.realtime_priority < 0 || cfg.dds.realtime_priority >= cfg.realtime.priority)
      throw ConfigError(d.key("realtime_priority"), "must be 0 (off) or 1..[loop] priority - 1 (the loop stays above DDS)");
    cfg.dds.telemetry_decimation = d.integer("telemetry_decimation", 1);
    if (cfg.dds.telemetry_decimation < 1 || cfg.dds.telemetry_decimation > 1000)
      throw ConfigError(d.key("telemetry_decimation"), "must be 1..1000 (publish every n-th cycle)");
    const std::string xml = d.string("config", "");
    if (cfg.dds_enabled && xml.empty())
      throw ConfigError(d.key("config"), "a Cyclone DDS XML configuration is required when DDS is enabled "
                                         "(bind the lab interface; config/cyclonedds-loopback.xml for tests)");
    if (!xml.empty()) {
      const std::filesystem::path p(xml);
      cfg.dds.config_path = (p.is_absolute() ? p : std::filesystem::path(path).parent_path() / p).string();
      if (cfg.dds_enabled && !std::filesystem::exists(cfg.dds.config_path))
        throw ConfigError(d.key("config"), "file '" + cfg.dds.config_path + "' not found");
    }
    d.finish();

    auto sp = top.table("setpoints");
    auto& l = cfg.setpoint_limits;
    const auto positive = [&](const char* key, double& v) {
      v = sp.number(key, v);
      if (!(v > 0.0)) throw ConfigError(sp.key(key), "must be positive");
    };
    l.min_um = sp.number("min_um", l.min_um);
    l.max_um = sp.number("max_um", l.max_um);
    if (!(l.max_um > l.min_um)) throw ConfigError(sp.key("max_um"), "must be above min_um");
    if (l.min_um < cfg.safety.sensor_min_um || l.max_um > cfg.safety.sensor_max_um)
      throw ConfigError(sp.key("max_um"), "the setpoint range must lie inside the sensor range [safety] sensor_min_um..sensor_max_um");
    positive("max_step_um", l.max_step_um);
    positive("max_slope_um_per_s", l.max_slope_um_per_s);
    l.min_V = sp.number("min_V", cfg.rig.controller.voltage_min_V);
    l.max_V = sp.number("max_V", cfg.rig.controller.voltage_max_V);
    if (l.min_V < cfg.rig.controller.voltage_min_V || l.max_V > cfg.rig.controller.voltage_max_V || !(l.max_V > l.min_V))
      throw ConfigError(sp.key("max_V"), "min_V..max_V must be a range inside [controller] voltage_min_V..voltage_max_V");
    positive("max_step_V", l.max_step_V);
    positive("max_slope_V_per_s", l.max_slope_V_per_s);
    positive("max_lead_s", l.max_lead_s);
    positive("past_tolerance_s", l.past_tolerance_s);
    l.max_chunk_samples = sp.integer("max_chunk_samples", l.max_chunk_samples);
    if (l.max_chunk_samples < 1 || l.max_chunk_samples > 1024)
      throw ConfigError(sp.key("max_chunk_samples"), "must be 1..1024 (the IDL's bound)");
    positive("max_chunks_per_s", l.max_chunks_per_s);
    positive("max_commands_per_s", l.max_commands_per_s);
    positive("burst_s", l.burst_s);
    sp.finish();
  });

  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ull;
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  cfg.config_hash = hex;
  return cfg;
}

}  // namespace pvcgel::daemon
