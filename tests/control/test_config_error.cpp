#include "control/config_error.hpp"

#include <gtest/gtest.h>

#include <string>

namespace pvcgel::control {
namespace {

TEST(ConfigError, CarriesKeyAndPrefixesTheMessage) {
  const ConfigError e("controller.pid.kp", "must be finite");
  EXPECT_EQ(e.key(), "controller.pid.kp");
  EXPECT_EQ(std::string(e.what()), "controller.pid.kp: must be finite");
  // Catchable as the standard base.
  try {
    throw ConfigError("a.b", "c");
  } catch (const std::runtime_error& base) {
    EXPECT_EQ(std::string(base.what()), "a.b: c");
  }
}

}  // namespace
}  // namespace pvcgel::control
