#pragma once
/// @file
/// Strict reading of TOML tables: typed getters with key-named errors, and
/// detection of unknown keys.

#include <toml++/toml.h>

#include <cmath>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "control/config_error.hpp"

namespace pvcgel::control {

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
    if (auto v = t_->get(k)->value_exact<int64_t>()) {
      if (*v < std::numeric_limits<int>::min() || *v > std::numeric_limits<int>::max())
        throw ConfigError(key(k), "integer " + std::to_string(*v) + " is out of range");
      return static_cast<int>(*v);
    }
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
  /// The raw node under k (nullptr when absent), marked as used: for shapes
  /// the typed getters do not cover (arrays of tables).
  const toml::node* node(const std::string& k) {
    used_.insert(k);
    return has(k) ? t_->get(k) : nullptr;
  }
  /// Mark a key as handled elsewhere (not reported as unknown).
  void skip(const std::string& k) { used_.insert(k); }
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

/// Runs fn; a ConfigError escaping it gets " (in <source>)" appended.
template <typename Fn>
void with_source(const std::string& source, const Fn& fn) {
  try {
    fn();
  } catch (const ConfigError& e) {
    throw ConfigError(e.key(), std::string(e.what()).substr(e.key().size() + 2) + " (in " + source + ")");
  }
}

}  // namespace pvcgel::control
