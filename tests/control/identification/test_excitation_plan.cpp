#include "control/identification/excitation_plan.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "control/config_error.hpp"

namespace pvcgel::control::identification {
namespace {

TEST(IdentExcitationPlan, DefaultIsThePapersGridInsideTheVoltageRange) {
  const auto plan = ExcitationPlan::from_grid({}, 1e-3);
  ASSERT_EQ(plan.points().size(), 63u);
  EXPECT_DOUBLE_EQ(plan.points().front().frequency_Hz, 0.1);
  EXPECT_DOUBLE_EQ(plan.points()[6].frequency_Hz, 10.0);
  EXPECT_NEAR(plan.points()[3].frequency_Hz, 1.0, 1e-12);  // log-spaced: 0.1 .. 10 in 7 steps hits 1 Hz
  for (const auto& p : plan.points()) {
    EXPECT_GE(p.bias_V - p.amplitude_V, 0.0);
    EXPECT_LE(p.bias_V + p.amplitude_V, 1000.0);
    EXPECT_GE(p.periods, 4);
    EXPECT_GE(p.periods / p.frequency_Hz, 10.0 - 1e-9);  // at least 10 s analysed
    // The commanded voltage over the whole experiment stays in range too.
    for (double t = 0.0; t < p.duration_s(); t += 0.01) {
      EXPECT_GE(p.voltage_V(t), -1e-9);
      EXPECT_LE(p.voltage_V(t), 1000.0 + 1e-9);
    }
  }
  EXPECT_GT(plan.total_duration_s(), 63 * 10.0);
}

TEST(IdentExcitationPlan, RefusesPointsOutsideZeroToThousandVolts) {
  ExcitationPlan::Grid g;
  g.amplitudes_V = {300.0};
  g.biases_V = {800.0};  // 800 + 300 = 1100 V
  try {
    (void)ExcitationPlan::from_grid(g, 1e-3);
    FAIL() << "accepted a sine reaching 1100 V";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "ident.plan");
    EXPECT_NE(std::string(e.what()).find("1100"), std::string::npos) << e.what();
  }
  g.biases_V = {200.0};  // 200 - 300 = -100 V: the electrodes would swap roles
  EXPECT_THROW((void)ExcitationPlan::from_grid(g, 1e-3), ConfigError);
  g.biases_V = {300.0};  // exactly 0 .. 600 V is fine
  EXPECT_NO_THROW((void)ExcitationPlan::from_grid(g, 1e-3));
}

TEST(IdentExcitationPlan, RefusesTooFewPeriodsAndTooHighFrequencies) {
  EXPECT_THROW(ExcitationPlan({SinePoint{300, 450, 1.0, 10.0, 2}}, 1e-3), ConfigError);
  EXPECT_THROW(ExcitationPlan({SinePoint{300, 450, 60.0, 10.0, 5}}, 1e-3), ConfigError);  // < 20 samples/period
  EXPECT_THROW(ExcitationPlan({SinePoint{-5, 450, 1.0, 10.0, 5}}, 1e-3), ConfigError);
  EXPECT_NO_THROW(ExcitationPlan({SinePoint{300, 450, 1.0, 10.0, 3}}, 1e-3));
}

}  // namespace
}  // namespace pvcgel::control::identification
