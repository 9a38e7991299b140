#include "control/config/config_parser.hpp"

#include <sstream>

#include "control/config_error.hpp"
#include "control/config/effect_config.hpp"
#include "control/config/toml_reader.hpp"

namespace pvcgel::control {

namespace {

HammersteinModel read_model(TableReader& t) {
  OddPolynomial f(t.numbers("poly"), t.key("poly"));
  TransferFunction G(t.numbers("G_num"), t.numbers("G_den"), t.key("G_num"));
  return {std::move(f), std::move(G)};
}

/// `[sim]`: the simulated truth (sampled at the controller's period).
SimRigConfig read_sim(TableReader& s, double sample_time_s) {
  SimRigConfig sc;
  sc.sample_time_s = sample_time_s;
  const int seed = s.integer("seed", static_cast<int>(sc.seed));
  if (seed < 0) throw ConfigError(s.key("seed"), "must be >= 0");
  sc.seed = static_cast<std::uint64_t>(seed);
  sc.io_delay_samples = s.integer("io_delay_samples", sc.io_delay_samples);
  sc.noise_sigma_um = s.number("noise_sigma_um", sc.noise_sigma_um);
  sc.quantization_um = s.number("quantization_um", sc.quantization_um);
  auto truth = s.table("truth");
  if (truth.present()) {
    sc.truth = read_model(truth);
    sc.added_effects = read_effect_tables(truth, "effect", sc.sample_time_s);
    truth.finish();
  }
  auto h = s.table("hysteresis");
  sc.hysteresis.enabled = h.boolean("enabled", sc.hysteresis.enabled);
  sc.hysteresis.alpha = h.number("alpha", sc.hysteresis.alpha);
  sc.hysteresis.saturation_V = h.number("saturation_V", sc.hysteresis.saturation_V);
  h.finish();
  auto cr = s.table("creep");
  sc.creep.enabled = cr.boolean("enabled", sc.creep.enabled);
  sc.creep.fraction = cr.number("fraction", sc.creep.fraction);
  sc.creep.time_constant_s = cr.number("time_constant_s", sc.creep.time_constant_s);
  cr.finish();
  s.finish();
  return sc;
}

/// `[controller.pid.<mode>]`: manual gains, one table for every mode.
void read_manual_gains(TableReader& pid, ControllerConfig& cc) {
  cc.tuning.reset();
  for (auto m : kAllModes) {
    const std::string name(to_string(m));
    auto g = pid.table(name);
    if (!g.present()) throw ConfigError(pid.key(name), "manual gains need a table for every mode");
    auto& gains = cc.gains[static_cast<size_t>(m)];
    gains = {g.number("kp", 0.0), g.number("ki", 0.0), g.number("kd", 0.0), g.number("tf_s", 0.0)};
    g.finish();
  }
  pid.finish();
}

/// `[controller.tuning]`: the loop-shaping target the gains are designed for.
TuningTarget read_tuning(TableReader& tuning) {
  TuningTarget t;
  t.crossover_rad_s = tuning.number("crossover_rad_s", t.crossover_rad_s);
  t.phase_margin_deg = tuning.number("phase_margin_deg", t.phase_margin_deg);
  t.derivative_ratio = tuning.number("derivative_ratio", t.derivative_ratio);
  t.derivative_filter_n = tuning.number("derivative_filter_n", t.derivative_filter_n);
  tuning.finish();
  return t;
}

/// `[controller]` and its sub-tables but the effects (read with [model], at the period read here).
void read_controller(TableReader& c, ControllerConfig& cc) {
  const std::string mode = c.string("mode", std::string(to_string(cc.mode)));
  if (auto m = parse_mode(mode)) cc.mode = *m;
  else throw ConfigError(c.key("mode"), "unknown mode '" + mode + "' (pid, inverse_pid, inverse_pid_dob, inverse_pid_dob_ff)");
  cc.sample_time_s = c.number("period_s", cc.sample_time_s);
  // 10 us .. 100 ms: faster than any sensor here can answer, slower than the gel's dynamics allow.
  if (!(cc.sample_time_s >= 1e-5 && cc.sample_time_s <= 0.1))
    throw ConfigError(c.key("period_s"), "must be in 1e-5..0.1 s (100 kHz .. 10 Hz), got " +
                                             (std::ostringstream() << cc.sample_time_s).str());
  cc.voltage_min_V = c.number("voltage_min_V", cc.voltage_min_V);
  cc.voltage_max_V = c.number("voltage_max_V", cc.voltage_max_V);
  cc.slew_limit_V_per_s = c.number("slew_limit_V_per_s", cc.slew_limit_V_per_s);
  cc.operating_point_um = c.number("operating_point_um", cc.operating_point_um);
  cc.antiwindup_tracking_time_s = c.number("antiwindup_tracking_time_s", cc.antiwindup_tracking_time_s);
  auto dob = c.table("dob");
  cc.dob_lambda_s = dob.number("lambda_s", cc.dob_lambda_s);
  cc.dob_q_order = dob.integer("q_order", cc.dob_q_order);
  dob.finish();
  auto ff = c.table("feedforward");
  cc.learning_memory_s = ff.number("learning_memory_s", cc.learning_memory_s);
  ff.finish();
  auto tuning = c.table("tuning");
  auto pid = c.table("pid");
  if (pid.present() && tuning.present())
    throw ConfigError(c.key("pid"), "give either [controller.tuning] or manual [controller.pid.*] gains, not both");
  if (pid.present()) read_manual_gains(pid, cc);
  else cc.tuning = read_tuning(tuning);
  c.finish();
}

}  // namespace

HammersteinModel parse_model(const toml::table& root, const std::string& source) {
  HammersteinModel m = paper_model(2);
  with_source(source, [&] {
    TableReader top(&root, "");
    auto model = top.table("model");
    if (!model.present()) throw ConfigError("model", "no [model] table");
    m = read_model(model);
  });
  return m;
}

SimRigConfig parse_simulated_rig(const toml::table& root, const std::string& source) {
  SimRigConfig sc;
  with_source(source, [&] {
    TableReader top(&root, "");
    auto c = top.table("controller");
    auto s = top.table("sim");
    sc = read_sim(s, c.number("period_s", ControllerConfig{}.sample_time_s));
    SimulatedRig rig_check(sc);
  });
  return sc;
}

RigConfiguration parse_configuration(const toml::table& root, const std::string& source,
                                     const std::vector<std::string>& other_tables) {
  RigConfiguration cfg;
  with_source(source, [&] {
    TableReader top(&root, "");
    for (const auto& t : other_tables) top.skip(t);
    auto model = top.table("model");
    if (model.present()) {
      cfg.model = read_model(model);
      cfg.controller.io_delay_samples = model.integer("io_delay_samples", cfg.controller.io_delay_samples);
    }

    auto c = top.table("controller");
    auto& cc = cfg.controller;
    read_controller(c, cc);
    // [[model.effect]]: what the model carries beyond f and G (sample-time dependent bounds).
    if (model.present()) {
      cc.effects = read_effect_tables(model, "effect", cc.sample_time_s);
      model.finish();
    }

    auto s = top.table("sim");
    cfg.sim = read_sim(s, cc.sample_time_s);
    top.finish();

    // Build once so every design-time check runs now, not when a loop starts.
    Controller check(cfg.model, cc);
    SimulatedRig rig_check(cfg.sim);
  });
  return cfg;
}

}  // namespace pvcgel::control
