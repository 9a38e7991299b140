#include "daemon/daemon_config.hpp"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "control/config/toml_reader.hpp"
#include "daemon/config_file.hpp"

namespace pvcgel::daemon {

using control::ConfigError;

namespace {

/// A finite value can still be absurd: each bound below is a physical one, named in the message.
void check_bound(control::TableReader& t, const char* key, double v, double lo, double hi, const std::string& why) {
  if (v >= lo && v <= hi) return;
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.6g is outside %.6g..%.6g: ", v, lo, hi);
  throw ConfigError(t.key(key), buf + why);
}

void parse_loop(control::TableReader& top, DaemonConfig& cfg) {
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
}

void parse_hal(control::TableReader& top, const toml::table& root, DaemonConfig& cfg) {
  auto hal = top.table("hal");
  cfg.hal = parse_hal_config(hal, cfg.realtime.period_s);
  cfg.hal_backend = cfg.hal.backend;
  if (cfg.hal.backend != "sim" && !root.contains("model"))
    throw ConfigError("model", "backend '" + cfg.hal.backend + "' drives a real rig and needs its own identified "
                               "[model] (pvcgel ident); the built-in default is the paper's actuator, whose inverse "
                               "would be wrong for this one");
}

/// [safety]: the output's slew limit first (the ramp and open-loop limits are bounded by it).
void parse_safety(control::TableReader& top, DaemonConfig& cfg) {
  auto s = top.table("safety");
  auto& sc = cfg.safety;
  const auto& cc = cfg.rig.controller;
  const double span_V = cc.voltage_max_V - cc.voltage_min_V;
  // A slew limit above the whole voltage range per loop cycle limits nothing.
  const double slew_bound = span_V / cfg.realtime.period_s;
  sc.output_slew_V_per_s = s.number("output_slew_V_per_s", std::min(sc.output_slew_V_per_s, slew_bound));
  check_bound(s, "output_slew_V_per_s", sc.output_slew_V_per_s, 1.0, slew_bound,
              "above the whole voltage range per cycle it limits nothing (set the amplifier's rating)");
  sc.ramp_down_V_per_s = s.number("ramp_down_V_per_s", sc.ramp_down_V_per_s);
  check_bound(s, "ramp_down_V_per_s", sc.ramp_down_V_per_s, 1.0, sc.output_slew_V_per_s,
              "the ramp to 0 V must be positive and no faster than the amplifier's slew limit output_slew_V_per_s");
  sc.sensor_min_um = s.number("sensor_min_um", sc.sensor_min_um);
  sc.sensor_max_um = s.number("sensor_max_um", sc.sensor_max_um);
  check_bound(s, "sensor_min_um", sc.sensor_min_um, -1e5, 1e5, "a displacement sensor range beyond +-100 mm is not a gel rig's");
  check_bound(s, "sensor_max_um", sc.sensor_max_um, -1e5, 1e5, "a displacement sensor range beyond +-100 mm is not a gel rig's");
  if (!(sc.sensor_max_um > sc.sensor_min_um)) throw ConfigError(s.key("sensor_max_um"), "must be above sensor_min_um");
  sc.sensor_stale_cycles = s.integer("sensor_stale_cycles", sc.sensor_stale_cycles);
  if (sc.sensor_stale_cycles < 0) throw ConfigError(s.key("sensor_stale_cycles"), "must be >= 0 (0: off)");
  sc.sensor_timeout_cycles = s.integer("sensor_timeout_cycles", sc.sensor_timeout_cycles);
  if (sc.sensor_timeout_cycles < 1) throw ConfigError(s.key("sensor_timeout_cycles"), "must be >= 1");
  const auto policy = s.string("stale_setpoint", "hold");
  if (const auto p = parse_enum<StaleSetpointPolicy>(policy)) sc.stale_setpoint = *p;
  else throw ConfigError(s.key("stale_setpoint"), "must be \"hold\" or \"ramp_down\"");
  sc.soft_start_s = s.number("soft_start_s", sc.soft_start_s);
  check_bound(s, "soft_start_s", sc.soft_start_s, 0.0, 600.0, "a soft start longer than 10 minutes is a trajectory");
  sc.open_loop_slew_V_per_s = s.number("open_loop_slew_V_per_s", std::min(sc.open_loop_slew_V_per_s, sc.output_slew_V_per_s));
  check_bound(s, "open_loop_slew_V_per_s", sc.open_loop_slew_V_per_s, 1.0, sc.output_slew_V_per_s,
              "open-loop setpoints are slew-limited within the amplifier's output_slew_V_per_s");
  s.finish();
}

void parse_run(control::TableReader& top, DaemonConfig& cfg) {
  auto run = top.table("run");
  cfg.trajectory = run.string("trajectory", "");
  cfg.duration_s = run.number("duration_s", cfg.duration_s);
  if (!(cfg.duration_s > 0.0)) throw ConfigError(run.key("duration_s"), "must be positive");
  run.finish();
}

void parse_dds(control::TableReader& top, DaemonConfig& cfg, const std::string& path) {
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
}

/// [setpoints]: what the validator and the safety envelope enforce.
void parse_setpoints(control::TableReader& top, DaemonConfig& cfg) {
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
  check_bound(sp, "max_step_um", l.max_step_um, 0.0, l.max_um - l.min_um, "a step larger than the setpoint range");
  positive("max_slope_um_per_s", l.max_slope_um_per_s);
  check_bound(sp, "max_slope_um_per_s", l.max_slope_um_per_s, 0.0, 1e5,
              "100 mm/s is far beyond any gel actuator's speed");
  l.min_V = sp.number("min_V", cfg.rig.controller.voltage_min_V);
  l.max_V = sp.number("max_V", cfg.rig.controller.voltage_max_V);
  if (l.min_V < cfg.rig.controller.voltage_min_V || l.max_V > cfg.rig.controller.voltage_max_V || !(l.max_V > l.min_V))
    throw ConfigError(sp.key("max_V"), "min_V..max_V must be a range inside [controller] voltage_min_V..voltage_max_V");
  positive("max_step_V", l.max_step_V);
  check_bound(sp, "max_step_V", l.max_step_V, 0.0, l.max_V - l.min_V, "a step larger than the voltage range");
  l.max_slope_V_per_s = std::min(l.max_slope_V_per_s, cfg.safety.output_slew_V_per_s);  // default within the amplifier's
  positive("max_slope_V_per_s", l.max_slope_V_per_s);
  check_bound(sp, "max_slope_V_per_s", l.max_slope_V_per_s, 0.0, cfg.safety.output_slew_V_per_s,
              "voltage setpoints cannot change faster than the amplifier's [safety] output_slew_V_per_s");
  positive("max_lead_s", l.max_lead_s);
  check_bound(sp, "max_lead_s", l.max_lead_s, 0.0, 3600.0, "the loop queues at most 32 s of samples; an hour is the bound");
  positive("past_tolerance_s", l.past_tolerance_s);
  check_bound(sp, "past_tolerance_s", l.past_tolerance_s, 0.0, 10.0, "a start more than 10 s late is not a start");
  l.max_chunk_samples = sp.integer("max_chunk_samples", l.max_chunk_samples);
  if (l.max_chunk_samples < 1 || l.max_chunk_samples > 1024)
    throw ConfigError(sp.key("max_chunk_samples"), "must be 1..1024 (the IDL's bound)");
  positive("max_chunks_per_s", l.max_chunks_per_s);
  positive("max_commands_per_s", l.max_commands_per_s);
  positive("burst_s", l.burst_s);
  check_bound(sp, "max_chunks_per_s", l.max_chunks_per_s, 0.0, 1e4, "more chunks per second than loop cycles");
  check_bound(sp, "max_commands_per_s", l.max_commands_per_s, 0.0, 1e3, "no operator sends 1000 commands per second");
  check_bound(sp, "burst_s", l.burst_s, 0.0, 60.0, "a burst longer than a minute is not a burst");
  sp.finish();
}

}  // namespace

DaemonConfig load_daemon_config(const std::string& path) {
  // Unreadable or unparsable files are configuration errors too (exit 2: systemd must not restart).
  const auto [root, text] = read_config_file(path, "--config");

  if (root.empty())
    throw ConfigError("--config", "'" + path + "' is empty (no table, no key); start from config/pvcgeld.toml or "
                                  "config/pvcgeld-sim.toml");

  DaemonConfig cfg;
  cfg.rig = control::parse_configuration(root, path, {"loop", "hal", "safety", "run", "dds", "setpoints"});
  cfg.realtime.period_s = cfg.rig.controller.sample_time_s;

  control::with_source(path, [&] {
    control::TableReader top(&root, "");
    parse_loop(top, cfg);
    parse_hal(top, root, cfg);
    parse_safety(top, cfg);
    parse_run(top, cfg);
    parse_dds(top, cfg, path);
    parse_setpoints(top, cfg);
  });
  // The controller's own output stage slews within the envelope (so its anti-windup and DOB see what is applied).
  auto& cc = cfg.rig.controller;
  if (cc.slew_limit_V_per_s <= 0.0 || cc.slew_limit_V_per_s > cfg.safety.output_slew_V_per_s)
    cc.slew_limit_V_per_s = cfg.safety.output_slew_V_per_s;

  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) h = (h ^ c) * 1099511628211ull;
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  cfg.config_hash = hex;
  return cfg;
}

}  // namespace pvcgel::daemon
