#include "control/polynomial_inverse.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "control/config_error.hpp"
#include "control/hammerstein_model.hpp"

namespace pvcgel::control {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Hints a caller might pass: good, at/outside either end, NaN and infinities.
const std::vector<double> kHints = {500.0, 0.0, 1000.0, -100.0, 2000.0, 1e300, kNaN, kInf, -kInf, 999.999};

class PaperFitInverse : public ::testing::TestWithParam<int> {};

TEST_P(PaperFitInverse, ForwardOfInverseReturnsRequest) {
  const auto f = paper_model(GetParam()).f;
  const PolynomialInverse inv(f, 0.0, 1000.0);
  const double w_max = f(1000.0);
  const int N = 2001;
  for (int i = 0; i < N; ++i) {
    // Requests spread over f(1 V)..f(1000 V); the tiny-w end is checked separately.
    const double w = f(1.0) + (w_max - f(1.0)) * i / (N - 1);
    for (double hint : kHints) {
      const double x = inv(w, hint);
      ASSERT_TRUE(x >= 0.0 && x <= 1000.0) << "w=" << w << " hint=" << hint;
      // Documented accuracy is 1e-12 relative in w; 1e-9 allows for f's own rounding.
      ASSERT_LE(std::abs(f(x) - w), 1e-9 * std::abs(w)) << "w=" << w << " hint=" << hint << " x=" << x;
    }
    EXPECT_LE(std::abs(f(inv(w)) - w), 1e-9 * std::abs(w)) << "no hint, w=" << w;
  }
}

TEST_P(PaperFitInverse, InverseOfForwardReturnsVoltage) {
  const auto f = paper_model(GetParam()).f;
  const PolynomialInverse inv(f, 0.0, 1000.0);
  for (int i = 0; i <= 4000; ++i) {
    const double x = 0.25 * i;  // 0..1000 V
    for (double hint : kHints) {
      const double xr = inv(f(x), hint);
      // 1e-12 relative in w maps to at most 3e-12 relative in x (x f'/f <= 3 for these fits,
      // which are convex with c2 >= 0); plus the documented 1e-12 V absolute floor.
      ASSERT_NEAR(xr, x, 1e-11 * x + 1e-12) << "x=" << x << " hint=" << hint;
    }
  }
}

TEST_P(PaperFitInverse, TinyRequestsMeetTheDocumentedAccuracy) {
  // Near 0 V the doc promises 1e-12 relative in w *or* 1e-12 V in x.
  const auto f = paper_model(GetParam()).f;
  const PolynomialInverse inv(f, 0.0, 1000.0);
  for (double x : {1e-9, 1e-6, 1e-3, 0.1, 0.7}) {
    for (double hint : kHints) {
      const double xr = inv(f(x), hint);
      const bool w_ok = std::abs(f(xr) - f(x)) <= 1e-12 * std::abs(f(x));
      const bool x_ok = std::abs(xr - x) <= 1e-12;
      EXPECT_TRUE(w_ok || x_ok) << "x=" << x << " hint=" << hint << " got " << xr;
    }
  }
}

TEST_P(PaperFitInverse, RequestsBeyondTheRangeReturnTheBound) {
  const auto f = paper_model(GetParam()).f;
  const PolynomialInverse inv(f, 0.0, 1000.0);
  EXPECT_EQ(inv(f(1000.0)), 1000.0);
  EXPECT_EQ(inv(2.0 * f(1000.0), 3.0), 1000.0);
  EXPECT_EQ(inv(kInf), 1000.0);
  EXPECT_EQ(inv(0.0), 0.0);
  EXPECT_EQ(inv(-5.0, 700.0), 0.0);
  EXPECT_EQ(inv(-kInf), 0.0);
  EXPECT_EQ(inv(kNaN, 400.0), 0.0);  // NaN fails towards the low voltage

  // A narrower range clamps at its own ends.
  const PolynomialInverse narrow(f, 100.0, 900.0);
  EXPECT_EQ(narrow.lower_V(), 100.0);
  EXPECT_EQ(narrow.upper_V(), 900.0);
  EXPECT_EQ(narrow(f(50.0)), 100.0);
  EXPECT_EQ(narrow(f(950.0)), 900.0);
  EXPECT_NEAR(narrow(f(321.0), 10.0), 321.0, 1e-9);  // inside: exact up to the solver tolerance
}

INSTANTIATE_TEST_SUITE_P(PaperFits, PaperFitInverse, ::testing::Values(1, 2),
                         [](const auto& param_info) { return "n" + std::to_string(param_info.param); });

TEST(PolynomialInverse, NonMonotoneCubicFitIsRejectedNamingTheTurnover) {
  const auto f = paper_model(3).f;
  const auto turn = f.first_turnover(1000.0);
  ASSERT_TRUE(turn.has_value());
  EXPECT_NEAR(*turn, 862.0, 1.0);
  try {
    PolynomialInverse inv(f, 0.0, 1000.0);
    FAIL() << "non-monotone f accepted on 0..1000 V";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "model.poly");
    const std::string msg = e.what();
    EXPECT_NE(msg.find("862"), std::string::npos) << msg;
    EXPECT_NE(msg.find("model.poly"), std::string::npos) << msg;
  }
}

TEST(PolynomialInverse, CubicFitBelowItsTurnoverIsUsable) {
  const auto f = paper_model(3).f;
  const PolynomialInverse inv(f, 0.0, 850.0);
  for (int i = 0; i <= 850; ++i) {
    const double x = static_cast<double>(i);
    // x f'/f <= 3 here as well (0.2 at 850 V), so 1e-12 relative in w is < 1e-11 in x: 1e-9 is ample.
    EXPECT_NEAR(inv(f(x), kNaN), x, 1e-9 * (1.0 + x)) << "x=" << x;
  }
  EXPECT_EQ(inv(f(860.0)), 850.0);
}

TEST(PolynomialInverse, RejectsBadRangesWithKey) {
  const auto f = paper_model(2).f;
  for (auto [lo, hi] : std::vector<std::pair<double, double>>{{-1.0, 100.0}, {10.0, 10.0}, {0.0, 1001.0}, {kNaN, 5.0}}) {
    try {
      PolynomialInverse inv(f, lo, hi, "controller.voltage");
      FAIL() << "range [" << lo << ", " << hi << "] accepted";
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), "controller.voltage");
    }
  }
}

}  // namespace
}  // namespace pvcgel::control
