#include "control/config_parser.hpp"

#include <cmath>
#include <set>

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {

/// Reads keys of one table, remembering which were used so leftovers can be
/// reported as unknown (a typo must not silently fall back to a default).
class TableReader {
 public:
  TableReader(const toml::table* t, std::string prefix) : t_(t), prefix_(std::move(prefix)) {}

  [[nodiscard]] std::string key(const std::string& k) const { return prefix_.empty() ? k : prefix_ + "." + k; }
  [[nodiscard]] bool has(const std::string& k) const { return t_ && t_->contains(k); }

  double number(const std::string& k, double fallback) {
    used_.insert(k);
    if (!has(k)) return fallback;
    const auto& node = *t_->get(k);
    if (auto v = node.value<double>()) {
      if (!std::isfinite(*v)) throw ConfigError(key(k), "must be a finite number");
      return *v;
    }
    throw ConfigError(key(k), "must be a number");
  }
  int integer(const std::string& k, int fallback) {
    used_.insert(k);
    if (!has(k)) return fallback;
    if (auto v = t_->get(k)->value_exact<int64_t>()) return static_cast<int>(*v);
    throw ConfigError(key(k), "must be an integer");
  }
  bool boolean(const std::string& k, bool fallback) {
    used_.insert(k);
    if (!has(k)) return fallback;
    if (auto v = t_->get(k)->value_exact<bool>()) return *v;
    throw ConfigError(key(k), "must be true or false");
  }
  std::string string(const std::string& k, const std::string& fallback) {
    used_.insert(k);
    if (!has(k)) return fallback;
    if (auto v = t_->get(k)->value_exact<std::string>()) return *v;
    throw ConfigError(key(k), "must be a string");
  }
  std::vector<double> numbers(const std::string& k) {
    used_.insert(k);
    if (!has(k)) throw ConfigError(key(k), "is required");
    const auto* arr = t_->get(k)->as_array();
    if (!arr || arr->empty()) throw ConfigError(key(k), "must be a non-empty array of numbers");
    std::vector<double> out;
    for (size_t i = 0; i < arr->size(); ++i) {
      auto v = (*arr)[i].value<double>();
      if (!v || !std::isfinite(*v))
        throw ConfigError(key(k) + "[" + std::to_string(i) + "]", "must be a finite number");
      out.push_back(*v);
    }
    return out;
  }
  TableReader table(const std::string& k) {
    used_.insert(k);
    if (!has(k)) return {nullptr, key(k)};
    const auto* sub = t_->get(k)->as_table();
    if (!sub) throw ConfigError(key(k), "must be a table");
    return {sub, key(k)};
  }
  [[nodiscard]] bool present() const { return t_ != nullptr; }
  void finish() const {
    if (!t_) return;
    for (const auto& [k, v] : *t_) {
      const std::string name(k.str());
      if (!used_.count(name)) throw ConfigError(key(name), "unknown key");
    }
  }

 private:
  const toml::table* t_;
  std::string prefix_;
  std::set<std::string> used_;
};

HammersteinModel read_model(TableReader& t) {
  OddPolynomial f(t.numbers("poly"), t.key("poly"));
  TransferFunction G(t.numbers("G_num"), t.numbers("G_den"), t.key("G_num"));
  return {std::move(f), std::move(G)};
}

void wrap_errors(const std::string& source, const auto& fn) {
  try {
    fn();
  } catch (const ConfigError& e) {
    throw ConfigError(e.key(), std::string(e.what()).substr(e.key().size() + 2) + " (in " + source + ")");
  }
}

}  // namespace

HammersteinModel parse_model(const toml::table& root, const std::string& source) {
  HammersteinModel m = paper_model(2);
  wrap_errors(source, [&] {
    TableReader top(&root, "");
    auto model = top.table("model");
    if (!model.present()) throw ConfigError("model", "no [model] table");
    m = read_model(model);
  });
  return m;
}

RigConfiguration parse_configuration(const toml::table& root, const std::string& source) {
  RigConfiguration cfg;
  wrap_errors(source, [&] {
    TableReader top(&root, "");
    auto model = top.table("model");
    if (model.present()) {
      cfg.model = read_model(model);
      cfg.controller.io_delay_samples = model.integer("io_delay_samples", cfg.controller.io_delay_samples);
      model.finish();
    }

    auto c = top.table("controller");
    auto& cc = cfg.controller;
    const std::string mode = c.string("mode", std::string(to_string(cc.mode)));
    if (auto m = parse_mode(mode)) cc.mode = *m;
    else throw ConfigError(c.key("mode"), "unknown mode '" + mode + "' (pid, inverse_pid, inverse_pid_dob, inverse_pid_dob_ff)");
    cc.sample_time_s = c.number("period_s", cc.sample_time_s);
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
    if (pid.present()) {
      cc.tuning.reset();
      for (auto m : kAllModes) {
        auto g = pid.table(std::string(to_string(m)));
        if (!g.present()) throw ConfigError(g.key(""), "manual gains need a table for every mode");
        auto& gains = cc.gains[static_cast<size_t>(m)];
        gains = {g.number("kp", 0.0), g.number("ki", 0.0), g.number("kd", 0.0), g.number("tf_s", 0.0)};
        g.finish();
      }
      pid.finish();
    } else {
      TuningTarget t;
      t.crossover_rad_s = tuning.number("crossover_rad_s", t.crossover_rad_s);
      t.phase_margin_deg = tuning.number("phase_margin_deg", t.phase_margin_deg);
      t.derivative_ratio = tuning.number("derivative_ratio", t.derivative_ratio);
      t.derivative_filter_n = tuning.number("derivative_filter_n", t.derivative_filter_n);
      tuning.finish();
      cc.tuning = t;
    }
    c.finish();

    auto s = top.table("sim");
    auto& sc = cfg.sim;
    sc.sample_time_s = cc.sample_time_s;
    sc.seed = static_cast<std::uint64_t>(s.integer("seed", static_cast<int>(sc.seed)));
    sc.io_delay_samples = s.integer("io_delay_samples", sc.io_delay_samples);
    sc.noise_sigma_um = s.number("noise_sigma_um", sc.noise_sigma_um);
    sc.quantization_um = s.number("quantization_um", sc.quantization_um);
    auto truth = s.table("truth");
    if (truth.present()) {
      sc.truth = read_model(truth);
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
    top.finish();

    // Build once so every design-time check runs now, not when a loop starts.
    Controller check(cfg.model, cc);
    SimulatedRig rig_check(sc);
  });
  return cfg;
}

}  // namespace pvcgel::control
