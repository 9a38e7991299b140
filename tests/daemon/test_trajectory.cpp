#include "daemon/trajectory.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>

#include "control/config_error.hpp"

using pvcgel::control::ConfigError;
using pvcgel::daemon::Trajectory;

TEST(Trajectory, PaperReferencesMatchThePaper) {
  const auto t = Trajectory::parse("paper-1hz");
  EXPECT_NEAR(t.at(0.25), 125.0, 1e-12);  // 100 + 25 sin(pi/2)
  const auto m = Trajectory::parse("paper-multi");
  const double tt = 1.3;
  const double expected = 33 + 5 * std::sin(0.2 * std::numbers::pi * tt) + 33 + 7 * std::sin(std::numbers::pi * tt) +
                          30 + 12 * std::sin(2 * std::numbers::pi * tt);
  EXPECT_NEAR(m.at(tt), expected, 1e-9);
  EXPECT_TRUE(std::isinf(t.end_s()));
}

TEST(Trajectory, ParametricSpecs) {
  EXPECT_DOUBLE_EQ(Trajectory::parse("hold:80").at(12.0), 80.0);
  EXPECT_NEAR(Trajectory::parse("sine:100,10,0.5").at(0.5), 110.0, 1e-9);
  EXPECT_NEAR(Trajectory::parse("multisine:90,5,1,2,0.25").at(1.0), 90.0 + 2.0, 1e-9);
}

TEST(Trajectory, CsvInterpolatesAndHoldsTheEnd) {
  const std::string path = ::testing::TempDir() + "traj.csv";
  std::ofstream(path) << "t_s,r_um\n0,100\n1,110\n2,90\n";
  const auto t = Trajectory::parse("csv:" + path);
  EXPECT_NEAR(t.at(0.5), 105.0, 1e-12);
  EXPECT_NEAR(t.at(1.5), 100.0, 1e-12);
  EXPECT_DOUBLE_EQ(t.at(5.0), 90.0);
  EXPECT_DOUBLE_EQ(t.end_s(), 2.0);
}

TEST(Trajectory, BadSpecsNameTheProblem) {
  auto message = [](const std::string& spec) {
    try {
      (void)Trajectory::parse(spec);
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), "trajectory");
      return std::string(e.what());
    }
    ADD_FAILURE() << "no error for " << spec;
    return std::string();
  };
  EXPECT_NE(message("wobble").find("unknown trajectory"), std::string::npos);
  EXPECT_NE(message("sine:1,2").find("expected"), std::string::npos);
  EXPECT_NE(message("sine:1,x,3").find("not a number"), std::string::npos);
  EXPECT_NE(message("sine:100,10,-1").find("positive"), std::string::npos);
  EXPECT_NE(message("csv:/nonexistent/x.csv").find("cannot open"), std::string::npos);
  const std::string path = ::testing::TempDir() + "bad.csv";
  std::ofstream(path) << "t_s,r_um\n0,100\n1,110\n0.5,90\n";
  EXPECT_NE(message("csv:" + path).find(":4: time must increase"), std::string::npos);
}
