#include "control/config/effect_config.hpp"

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {

/// One effect table: `name` plus its parameters (optional ones take their default).
Effect read_one(TableReader& t, const std::string& table_key, double sample_time_s) {
  const std::string name = t.string("name", "");
  const auto kind = parse_effect_kind(name);
  if (!kind || *kind == EffectKind::none) {
    std::string known;
    for (auto k : kCandidateEffects) known += (known.empty() ? "" : ", ") + std::string(to_string(k));
    throw ConfigError(t.key("name"), "unknown effect '" + name + "' (" + known + ")");
  }
  Effect e{*kind, {}};
  const auto specs = parameter_specs(*kind, DataScale::unbounded(sample_time_s));
  for (size_t i = 0; i < specs.size(); ++i) {
    if (!t.has(specs[i].name) && std::isnan(specs[i].default_value))
      throw ConfigError(t.key(specs[i].name), "is required for a " + name + " effect");
    e.p[i] = t.number(specs[i].name, specs[i].default_value);
  }
  t.finish();
  validate(e, sample_time_s, table_key);
  return e;
}

}  // namespace

std::vector<Effect> read_effect_tables(TableReader& parent, const std::string& key, double sample_time_s) {
  const toml::node* node = parent.node(key);
  std::vector<Effect> effects;
  if (!node) return effects;
  const std::string base = parent.key(key);
  if (const auto* table = node->as_table()) {
    TableReader t(table, base);
    effects.push_back(read_one(t, base, sample_time_s));
  } else if (const auto* array = node->as_array()) {
    for (size_t i = 0; i < array->size(); ++i) {
      const std::string item = base + "[" + std::to_string(i) + "]";
      const auto* element = (*array)[i].as_table();
      if (!element) throw ConfigError(item, "must be a table ([[" + base + "]])");
      TableReader t(element, item);
      effects.push_back(read_one(t, item, sample_time_s));
    }
    if (effects.empty()) throw ConfigError(base, "is an empty list: omit it for no effect");
  } else {
    throw ConfigError(base, "must be a table or an array of tables ([[" + base + "]])");
  }
  validate_mixture(effects, base);
  return effects;
}

}  // namespace pvcgel::control
