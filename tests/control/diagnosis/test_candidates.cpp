// Which fitted candidates the recordings can show as their physics (control/diagnosis/candidates.hpp):
// a dead zone is observed only when some recorded command comes within a factor 10 of its threshold.
#include "control/diagnosis/candidates.hpp"

#include <gtest/gtest.h>

namespace pvcgel::control::diagnosis::detail {
namespace {

DataScale commands_between(double u_min_V, double u_max_V) {
  DataScale s;
  s.u_min_V = u_min_V;
  s.u_max_V = u_max_V;
  return s;
}

Effect dead_zone_at(double threshold_V, double catch_up_V) { return Effect{EffectKind::dead_zone, {threshold_V, catch_up_V}}; }

TEST(UnobservedBy, ADeadZoneFarBelowEveryRecordedCommandIsUnobservedAndTheReasonGivesBothVoltages) {
  // Evaluation case134: a closed loop about 390 V, its dead zone candidate fitted at 10.6 V.
  const std::string why = unobserved_by(dead_zone_at(10.59, 422.0), commands_between(323.5, 455.5));
  EXPECT_NE(why.find("threshold (10.6 V)"), std::string::npos) << why;
  EXPECT_NE(why.find("smallest recorded |command| (324 V)"), std::string::npos) << why;
}

TEST(UnobservedBy, ADeadZoneWithinAFactorTenOfTheSmallestCommandIsObserved) {
  // Evaluation case234: the smallest command 27.7 V, the threshold 5.41 V (5.1x), named rightly.
  EXPECT_EQ(unobserved_by(dead_zone_at(5.41, 32.0), commands_between(27.7, 85.7)), "");
  EXPECT_EQ(unobserved_by(dead_zone_at(32.4, 100.0), commands_between(323.5, 455.5)), "");
  EXPECT_NE(unobserved_by(dead_zone_at(32.3, 100.0), commands_between(323.5, 455.5)), "");
}

TEST(UnobservedBy, CommandsFromOrThroughZeroReachEveryThreshold) {
  EXPECT_EQ(unobserved_by(dead_zone_at(0.5, 10.0), commands_between(0.0, 450.0)), "");
  EXPECT_EQ(unobserved_by(dead_zone_at(0.5, 10.0), commands_between(-150.0, 150.0)), "");
  // Negative commands only (a drive wired the other way): the nearest is the largest, -40 V.
  EXPECT_NE(unobserved_by(dead_zone_at(3.0, 10.0), commands_between(-450.0, -40.0)), "");
  EXPECT_EQ(unobserved_by(dead_zone_at(5.0, 10.0), commands_between(-450.0, -40.0)), "");
}

TEST(UnobservedBy, OtherEffectsAreAlwaysObserved) {
  const DataScale far_from_zero = commands_between(323.5, 455.5);
  EXPECT_EQ(unobserved_by(Effect{EffectKind::hysteresis, {0.05, 10.9, 0.0}}, far_from_zero), "");
  EXPECT_EQ(unobserved_by(Effect{EffectKind::saturation, {40.0, 5.0, 0.0, 0.0}}, far_from_zero), "");
}

}  // namespace
}  // namespace pvcgel::control::diagnosis::detail
