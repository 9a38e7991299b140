#pragma once
/// @file
/// The one exception type thrown at configuration time.

#include <stdexcept>
#include <string>

namespace pvcgel::control {

/// Raised while building controllers, models or rigs from parameters that are
/// unsafe or inconsistent. `key()` names the configuration key at fault (for
/// example "controller.pid.kp"), so the message a user sees says where to look.
/// Never thrown from the real-time path.
class ConfigError final : public std::runtime_error {
 public:
  /// @param key  dotted configuration key the problem belongs to
  /// @param reason  what is wrong and, where possible, what would be accepted
  ConfigError(std::string key, const std::string& reason)
      : std::runtime_error(key + ": " + reason), key_(std::move(key)) {}

  /// Dotted configuration key at fault.
  [[nodiscard]] const std::string& key() const noexcept { return key_; }

 private:
  std::string key_;
};

}  // namespace pvcgel::control
