#include "control/output_stage.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace pvcgel::control {
namespace {

TEST(OutputStage, ClampsAndMapsNaNToMin) {
  OutputStage s(10.0, 900.0, 0.0, 1e-3);
  EXPECT_EQ(s.min_V(), 10.0);
  EXPECT_EQ(s.max_V(), 900.0);
  EXPECT_EQ(s.apply(5.0), 10.0);
  EXPECT_EQ(s.apply(1e6), 900.0);
  EXPECT_EQ(s.apply(std::nan("")), 10.0);
  EXPECT_EQ(s.apply(-INFINITY), 10.0);
  EXPECT_EQ(s.apply(123.0), 123.0);
  EXPECT_EQ(s.last_V(), 123.0);
}

TEST(OutputStage, SlewLimitsPerSample) {
  OutputStage slew(0.0, 1000.0, 1000.0, 1e-3);  // 1000 V/s at 1 kHz: 1 V per sample
  slew.reset(100.0);
  EXPECT_EQ(slew.apply(200.0), 101.0);
  EXPECT_EQ(slew.apply(200.0), 102.0);
  EXPECT_EQ(slew.apply(0.0), 101.0);
  EXPECT_EQ(slew.apply(101.5), 101.5);
  EXPECT_EQ(slew.apply(std::nan("")), 100.5);  // NaN -> min, then slew-limited towards it
  slew.reset(5000.0);
  EXPECT_EQ(slew.last_V(), 1000.0);  // reset clamps too
  OutputStage free(0.0, 1000.0, 0.0, 1e-3);  // 0 disables the slew limit
  free.reset(0.0);
  EXPECT_EQ(free.apply(1000.0), 1000.0);
}

}  // namespace
}  // namespace pvcgel::control
