#include "control/lti_filter.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "control/config_error.hpp"

namespace pvcgel::control {
namespace {

DiscreteTransferFunction dtf(std::initializer_list<double> b, std::initializer_list<double> a) {
  DiscreteTransferFunction h;
  h.b = Eigen::Map<const Eigen::VectorXd>(b.begin(), static_cast<Eigen::Index>(b.size()));
  h.a = Eigen::Map<const Eigen::VectorXd>(a.begin(), static_cast<Eigen::Index>(a.size()));
  return h;
}

TEST(LtiFilter, SteadyStateResetHasNoTransient) {
  const auto h = dtf({0.0, 0.3, 0.1}, {1.0, -1.1, 0.3});  // poles 0.5, 0.6; H(1) = 0.4 / 0.2 = 2
  LtiFilter f(realize(h));
  EXPECT_EQ(f.order(), 2);
  EXPECT_NEAR(f.dc_gain(), 2.0, 1e-13);
  f.reset_steady_state(3.0);
  for (int k = 0; k < 50; ++k) {
    EXPECT_NEAR(f.peek(3.0), 6.0, 1e-12);  // steady state exactly (rounding only)
    EXPECT_NEAR(f.step(3.0), 6.0, 1e-12);
  }
  f.reset();
  EXPECT_EQ(f.peek(0.0), 0.0);
  EXPECT_EQ(f.step(1.0), 0.0);      // one sample of delay
  EXPECT_NEAR(f.step(1.0), 0.3, 1e-15);  // then b1
}

TEST(LtiFilter, PeekDoesNotAdvance) {
  LtiFilter f(realize(dtf({0.2, 0.1}, {1.0, -0.7})));
  f.step(1.0);
  const double p = f.peek(2.0);
  EXPECT_EQ(f.peek(2.0), p);
  EXPECT_EQ(f.step(2.0), p);
  EXPECT_NE(f.peek(2.0), p);
}

TEST(LtiFilter, IntegratorHasNoSteadyState) {
  LtiFilter f(realize(dtf({0.0, 1.0}, {1.0, -1.0})));
  EXPECT_TRUE(std::isnan(f.dc_gain()));
  for (int k = 0; k < 5; ++k) f.step(1.0);
  EXPECT_NEAR(f.peek(0.0), 5.0, 1e-15);
  f.reset_steady_state(7.0);  // documented: zeroes the state
  EXPECT_EQ(f.peek(0.0), 0.0);
}

TEST(LtiFilter, PureGainAndOrderLimit) {
  LtiFilter g(realize(dtf({2.5}, {1.0})));
  EXPECT_EQ(g.order(), 0);
  EXPECT_EQ(g.step(2.0), 5.0);
  EXPECT_EQ(g.dc_gain(), 2.5);

  Eigen::VectorXd a = Eigen::VectorXd::Zero(12);
  a(0) = 1.0;
  a(11) = 0.1;
  const DiscreteTransferFunction big{Eigen::VectorXd::Ones(1), a};
  EXPECT_THROW(LtiFilter{realize(big)}, ConfigError);
  a.conservativeResize(11);
  a(10) = 0.1;
  EXPECT_NO_THROW(LtiFilter{realize(DiscreteTransferFunction{Eigen::VectorXd::Ones(1), a})});
}

}  // namespace
}  // namespace pvcgel::control
