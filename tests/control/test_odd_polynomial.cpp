#include "control/odd_polynomial.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "control/config_error.hpp"
#include "control/hammerstein_model.hpp"

namespace pvcgel::control {
namespace {

// b1 / A by the trapezoid rule over one period. The integrand f(B + A sin t) sin t is a
// trigonometric polynomial of degree 2n, which the M-point periodic trapezoid rule
// integrates exactly for M > 2n, so only rounding remains.
double fourier_gain(const OddPolynomial& f, double A, double B, int M = 20000) {
  double sum = 0.0;
  for (int j = 0; j < M; ++j) {
    const double t = 2.0 * std::numbers::pi * j / M;
    sum += f(B + A * std::sin(t)) * std::sin(t);
  }
  // (1/pi) * (2 pi / M) * sum, then divide by A.
  return 2.0 * sum / M / A;
}

// Largest |f| over the orbit: the scale of the rounding error of the trapezoid sum.
double orbit_scale(const OddPolynomial& f, double A, double B) {
  return std::max(std::abs(f(B + A)), std::abs(f(B - A)));
}

std::vector<std::vector<double>> test_polynomials() {
  return {
      {1.3664},                                     // paper n = 1
      {0.1270, 1.3057e-5},                          // paper n = 2
      {0.0721, 2.1307e-5, -1.7231e-11},             // paper n = 3
      {0.05, 2.0e-5, -1.0e-11, 3.0e-18},            // n = 4, made up but same scale
  };
}

TEST(OddPolynomial, EvaluatesValueAndDerivative) {
  const OddPolynomial f({0.0721, 2.1307e-5, -1.7231e-11});
  for (double x : {-700.0, -1.0, 0.0, 0.5, 123.0, 862.0, 1000.0}) {
    const double expected = 0.0721 * x + 2.1307e-5 * x * x * x - 1.7231e-11 * std::pow(x, 5);
    const double dexpected = 0.0721 + 3.0 * 2.1307e-5 * x * x - 5.0 * 1.7231e-11 * std::pow(x, 4);
    // Horner vs. direct sum of three terms: a few ulps of the largest term.
    EXPECT_NEAR(f(x), expected, 1e-13 * (1.0 + std::abs(expected)) + 1e-12) << "x=" << x;
    EXPECT_NEAR(f.derivative(x), dexpected, 1e-13 + 1e-12 * std::abs(dexpected)) << "x=" << x;
    double v, d;
    f.evaluate(x, v, d);
    EXPECT_EQ(v, f(x));
    EXPECT_EQ(d, f.derivative(x));
  }
  EXPECT_EQ(f(-3.0), -f(3.0));  // odd
  EXPECT_EQ(f.terms(), 3);
  EXPECT_EQ(f.coefficient(2), 2.1307e-5);
  EXPECT_EQ(f.coefficients(), (std::vector<double>{0.0721, 2.1307e-5, -1.7231e-11}));
}

TEST(OddPolynomial, RejectsBadCoefficientsWithKey) {
  EXPECT_THROW(OddPolynomial(std::vector<double>{}), ConfigError);
  EXPECT_THROW(OddPolynomial(std::vector<double>(9, 1.0)), ConfigError);
  try {
    OddPolynomial({1.0, std::numeric_limits<double>::quiet_NaN()}, "my.key");
    FAIL() << "NaN coefficient accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "my.key");
    EXPECT_NE(std::string(e.what()).find("c2"), std::string::npos) << e.what();
  }
}

TEST(OddPolynomial, DescribingFunctionMatchesFourierIntegral) {
  // The paper's operating range (A in {300,350,400}, B in {400,450,500}) plus
  // pure sinusoids (B = 0), small signals and A > B (the orbit crosses zero).
  const std::vector<std::pair<double, double>> ab = {
      {300, 400}, {300, 450}, {300, 500}, {350, 400}, {350, 450}, {350, 500}, {400, 400},
      {400, 450}, {400, 500}, {100, 0},   {500, 0},   {1, 300},   {250, 100}, {20, 800}};
  for (const auto& c : test_polynomials()) {
    const OddPolynomial f(c);
    for (const auto& [A, B] : ab) {
      const double N = f.describing_function(A, B);
      const double ref = fourier_gain(f, A, B);
      // Rounding of a 20000-term sum of values up to orbit_scale, relative to b1 = N A:
      // ~ sqrt(M) eps scale / (A |N|); 1e-10 of the scale/A ratio leaves a wide margin.
      const double tol = 1e-10 * orbit_scale(f, A, B) / A;
      EXPECT_NEAR(N, ref, tol) << "n=" << c.size() << " A=" << A << " B=" << B;
    }
  }
}

TEST(OddPolynomial, DescribingFunctionMatchesPaperEquation7) {
  // Paper eq. (7), n = 2: N = c1 + 3 c2 (B^2 + A^2 / 4).
  const double c1 = 0.1270, c2 = 1.3057e-5;
  const OddPolynomial f({c1, c2});
  for (double A : {300.0, 350.0, 400.0}) {
    for (double B : {400.0, 450.0, 500.0}) {
      const double closed_form = c1 + 3.0 * c2 * (B * B + A * A / 4.0);
      // Same algebra summed in a different order: a few ulps.
      EXPECT_NEAR(f.describing_function(A, B), closed_form, 1e-14 * closed_form) << "A=" << A << " B=" << B;
    }
  }
  // The paper model uses exactly these coefficients.
  EXPECT_EQ(paper_model(2).f.coefficients(), (std::vector<double>{c1, c2}));
}

TEST(OddPolynomial, DescribingFunctionBasisIsConsistent) {
  for (const auto& c : test_polynomials()) {
    const OddPolynomial f(c);
    const int n = f.terms();
    for (const auto& [A, B] : std::vector<std::pair<double, double>>{{300, 400}, {400, 500}, {50, 0}, {10, 900}}) {
      const Eigen::VectorXd h = OddPolynomial::describing_function_basis(n, A, B);
      ASSERT_EQ(h.size(), n);
      double dot = 0.0;
      for (int i = 0; i < n; ++i) dot += h(i) * c[static_cast<size_t>(i)];
      // describing_function is documented as this dot product: equal up to summation order.
      EXPECT_NEAR(f.describing_function(A, B), dot, 1e-14 * std::abs(dot));
      // Element i is the gain of the monomial x^(2i+1) alone.
      for (int i = 0; i < n; ++i) {
        std::vector<double> mono(static_cast<size_t>(i + 1), 0.0);
        mono.back() = 1.0;
        const OddPolynomial m(mono);
        const double ref = fourier_gain(m, A, B);
        EXPECT_NEAR(h(i), ref, 1e-10 * orbit_scale(m, A, B) / A) << "i=" << i << " A=" << A << " B=" << B;
      }
    }
  }
  // Closed forms of the first two elements: 1 and 3 (B^2 + A^2/4).
  const Eigen::VectorXd h = OddPolynomial::describing_function_basis(2, 300.0, 400.0);
  EXPECT_DOUBLE_EQ(h(0), 1.0);
  EXPECT_DOUBLE_EQ(h(1), 3.0 * (400.0 * 400.0 + 300.0 * 300.0 / 4.0));
}

TEST(OddPolynomial, FirstTurnoverOfPaperCubicFitIsNear862V) {
  const auto f = paper_model(3).f;
  const auto turn = f.first_turnover(1000.0);
  ASSERT_TRUE(turn.has_value());
  // f'(x) = c1 + 3 c2 z + 5 c3 z^2 with z = x^2: the positive root of the quadratic.
  const double c1 = 0.0721, c2 = 2.1307e-5, c3 = -1.7231e-11;
  const double z = (-3.0 * c2 - std::sqrt(9.0 * c2 * c2 - 20.0 * c3 * c1)) / (10.0 * c3);
  EXPECT_NEAR(*turn, std::sqrt(z), 1e-6 * std::sqrt(z));  // root finder vs. closed form
  EXPECT_NEAR(*turn, 862.0, 1.0);
  EXPECT_NEAR(f.derivative(*turn), 0.0, 1e-9);
  EXPECT_GT(f.derivative(*turn - 1.0), 0.0);
  EXPECT_LT(f.derivative(*turn + 1.0), 0.0);
  // Below the turnover the range is usable.
  EXPECT_FALSE(f.first_turnover(850.0).has_value());
  // The n = 1 and n = 2 fits are increasing everywhere on 0..1000 V.
  EXPECT_FALSE(paper_model(1).f.first_turnover(1000.0).has_value());
  EXPECT_FALSE(paper_model(2).f.first_turnover(1000.0).has_value());
  // Decreasing at the origin: turnover at 0.
  const auto neg = OddPolynomial({-1.0, 1e-5}).first_turnover(1000.0);
  ASSERT_TRUE(neg.has_value());
  EXPECT_EQ(*neg, 0.0);
}

TEST(OddPolynomial, DoubleRootOfDerivativeIsNotATurnover) {
  // f(x) = x - x^3/3 * 2/a^2 + x^5/(5 a^4): f'(x) = (1 - x^2/a^2)^2 >= 0 touches zero at a
  // without changing sign, so f keeps increasing there.
  const double a = 500.0;
  const OddPolynomial f({1.0, -2.0 / (3.0 * a * a), 1.0 / (5.0 * a * a * a * a)});
  EXPECT_NEAR(f.derivative(a), 0.0, 1e-12);
  EXPECT_FALSE(f.first_turnover(1000.0).has_value());
}

}  // namespace
}  // namespace pvcgel::control
