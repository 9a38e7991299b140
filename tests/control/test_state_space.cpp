#include "control/state_space.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>

#include "control/config_error.hpp"
#include "control/lti_filter.hpp"

namespace pvcgel::control {
namespace {

const TransferFunction kPaperG({1.15, 1.03}, {1.0, 17.11, 8.76});

// Unit-step response of (b1 s + b0) / (s^2 + a1 s + a0) with distinct real poles, by
// partial fractions of G(s)/s: y(t) = G(0) + sum_i N(p_i) / (p_i (p_i - p_j)) e^{p_i t}.
double analytic_step(double t) {
  const double b1 = 1.15, b0 = 1.03, a1 = 17.11, a0 = 8.76;
  const double d = std::sqrt(a1 * a1 - 4.0 * a0);
  const double p1 = (-a1 + d) / 2.0, p2 = (-a1 - d) / 2.0;
  const double r1 = (b1 * p1 + b0) / (p1 * (p1 - p2));
  const double r2 = (b1 * p2 + b0) / (p2 * (p2 - p1));
  return b0 / a0 + r1 * std::exp(p1 * t) + r2 * std::exp(p2 * t);
}

TEST(StateSpace, RealizeReproducesTheTransferFunction) {
  const StateSpace ss = realize(kPaperG);
  ASSERT_EQ(ss.order(), 2);
  EXPECT_EQ(ss.D, 0.0);
  for (double w : {0.0, 0.1, 1.0, 17.0, 300.0}) {
    const std::complex<double> s(0.0, w);
    const Eigen::MatrixXcd M = s * Eigen::MatrixXcd::Identity(2, 2) - ss.A.cast<std::complex<double>>();
    const std::complex<double> h =
        (ss.C.cast<std::complex<double>>() * M.inverse() * ss.B.cast<std::complex<double>>())(0) + ss.D;
    // 2x2 solve of a well-conditioned system: rounding only.
    EXPECT_NEAR(std::abs(h - kPaperG(s)), 0.0, 1e-14) << "w=" << w;
  }
  // Biproper: D is the ratio of leading coefficients.
  const StateSpace bp = realize(TransferFunction({2.0, 3.0}, {4.0, 1.0}));
  EXPECT_DOUBLE_EQ(bp.D, 0.5);
  // Improper: rejected with the key given.
  try {
    (void)realize(TransferFunction({1.0, 0.0, 0.0}, {1.0, 1.0}), "some.key");
    FAIL() << "improper TF realised";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "some.key");
  }
}

TEST(StateSpace, ZohStepResponseIsExactAtTheSamples) {
  const double Ts = 1e-3;
  LtiFilter filter(discretize_zoh(realize(kPaperG), Ts));
  const double scale = kPaperG.dc_gain();
  double worst = 0.0;
  for (int k = 0; k <= 8000; ++k) {  // 8 s: past 4 time constants of the slow pole (1/0.53 s)
    const double y = filter.step(1.0);
    worst = std::max(worst, std::abs(y - analytic_step(k * Ts)));
  }
  // ZOH is exact for a piecewise-constant input; what remains is the matrix exponential's
  // rounding (~1e-16) accumulated over 8000 steps of a contracting recursion: << 1e-9.
  EXPECT_LE(worst, 1e-9 * scale);
  // And the comparison covered the whole transient: the slow pole (-0.53 1/s, residue -0.05)
  // leaves 0.6% of G(0) after 8 s.
  EXPECT_GT(filter.peek(1.0), 0.99 * scale);
  EXPECT_LT(filter.peek(1.0), scale);
}

TEST(StateSpace, ZohTransferFunctionHasMappedPolesAndDcGain) {
  const double Ts = 1e-3;
  const auto gd = to_transfer_function(discretize_zoh(realize(kPaperG), Ts));
  ASSERT_EQ(gd.a.size(), 3);
  ASSERT_EQ(gd.b.size(), 3);
  EXPECT_EQ(gd.a(0), 1.0);
  EXPECT_EQ(gd.b(0), 0.0);  // strictly proper G: one sample of delay from the hold
  EXPECT_EQ(gd.delay_samples(), 1);
  EXPECT_NEAR(gd.dc_gain(), kPaperG.dc_gain(), 1e-10 * kPaperG.dc_gain());
  // Poles map as z = exp(p Ts).
  const auto zp = gd.poles();
  const auto sp = kPaperG.poles();
  ASSERT_EQ(zp.size(), 2);
  for (const auto& p : sp) {
    const std::complex<double> expected = std::exp(p * Ts);
    const double dist = std::min(std::abs(zp(0) - expected), std::abs(zp(1) - expected));
    EXPECT_LT(dist, 1e-12) << "pole " << p;
  }
  // Frequency response approaches G(jw) well below Nyquist; ZOH adds a half-sample delay.
  const double w = 2.0;
  const auto h = gd.frequency_response(w, Ts) * std::polar(1.0, w * Ts / 2.0);
  // At w Ts = 2e-3 the ZOH is G(jw) up to O((w Ts)^2) ~ 1e-6 relative.
  EXPECT_NEAR(std::abs(h - kPaperG(std::complex<double>(0.0, w))), 0.0, 1e-5 * std::abs(kPaperG({0.0, w})));
}

TEST(StateSpace, ZohOfABadlyScaledBlockMapsItsPoles) {
  // A fast G (1.28e6 / (s^2 + 2723 s + 1.62e6)) driving a 313 Hz mode of damping 0.012 through G's own
  // output, realised in parts: one entry is wn^2 times G's numerator, 5e12, beside entries of order 1. Its
  // exponential at 10 kHz once came out with an eigenvalue of 8.2 (balancing fixes it).
  const double a1 = 2720.5, a0 = 1.6189e6, b0 = 1.28403e6, wn = 2.0 * std::numbers::pi * 312.602, zeta = 0.0124488;
  StateSpace c;
  c.A = Eigen::MatrixXd::Zero(4, 4);
  c.A(0, 0) = -a1, c.A(0, 1) = -a0, c.A(1, 0) = 1.0;
  c.A(2, 3) = 1.0, c.A(3, 2) = -wn * wn, c.A(3, 3) = -2.0 * zeta * wn, c.A(3, 1) = wn * wn * b0;
  c.B = Eigen::VectorXd::Unit(4, 0);
  c.C = Eigen::RowVectorXd::Unit(4, 2);
  const double Ts = 1e-4;
  const Eigen::VectorXcd z = discretize_zoh(c, Ts).A.eigenvalues(), s = c.A.eigenvalues();
  for (const auto& p : s) {
    double nearest = INFINITY;
    for (const auto& q : z) nearest = std::min(nearest, std::abs(q - std::exp(p * Ts)));
    EXPECT_LT(nearest, 1e-6) << "pole " << p;  // eigenvalues of so non-normal a matrix are themselves good to ~1e-7
  }
  for (const auto& q : z) EXPECT_LT(std::abs(q), 1.0);
}

TEST(StateSpace, TustinOfFirstOrderLagMatchesBilinearCoefficients) {
  const double Ts = 0.1;
  const auto h = to_transfer_function(discretize_tustin(realize(TransferFunction({1.0}, {1.0, 1.0})), Ts));
  // s = (2/Ts)(1 - z^-1)/(1 + z^-1): 1/(s+1) = Ts/(2+Ts) (1 + z^-1) / (1 + (Ts-2)/(Ts+2) z^-1).
  ASSERT_EQ(h.b.size(), 2);
  ASSERT_EQ(h.a.size(), 2);
  EXPECT_NEAR(h.b(0), Ts / (2.0 + Ts), 1e-15);
  EXPECT_NEAR(h.b(1), Ts / (2.0 + Ts), 1e-15);
  EXPECT_EQ(h.a(0), 1.0);
  EXPECT_NEAR(h.a(1), (Ts - 2.0) / (Ts + 2.0), 1e-15);

  // Second order, against the substitution evaluated at z on the unit circle.
  const TransferFunction g({1.15, 1.03}, {1.0, 17.11, 8.76});
  const auto hd = to_transfer_function(discretize_tustin(realize(g), Ts));
  for (double w : {0.5, 3.0, 20.0}) {
    const std::complex<double> z = std::polar(1.0, w * Ts);
    const std::complex<double> s = (2.0 / Ts) * (z - 1.0) / (z + 1.0);
    EXPECT_NEAR(std::abs(hd.frequency_response(w, Ts) - g(s)), 0.0, 1e-13) << "w=" << w;
  }
}

TEST(StateSpace, DiscreteRealizationRoundTrips) {
  struct Case {
    std::vector<double> b, a;
  };
  const Case cases[] = {
      {{0.5, 0.2, -0.1}, {1.0, -1.2, 0.35}},          // same length
      {{0.0, 0.3}, {1.0, -0.5, 0.06}},                // strictly proper, shorter numerator
      {{2.0, -1.0, 0.25, 0.1}, {1.0, 0.4}},           // longer numerator (FIR part)
      {{1.0, 0.5}, {2.0, -1.0, 0.5}},                 // a(0) != 1: normalised
      {{0.0, 0.0, 0.0, 0.04}, {1.0, -0.9}},           // pure delays
  };
  for (const auto& c : cases) {
    const DiscreteTransferFunction h{Eigen::Map<const Eigen::VectorXd>(c.b.data(), static_cast<Eigen::Index>(c.b.size())),
                                     Eigen::Map<const Eigen::VectorXd>(c.a.data(), static_cast<Eigen::Index>(c.a.size()))};
    const auto back = to_transfer_function(realize(h));
    const Eigen::Index n = std::max(h.a.size(), h.b.size());
    ASSERT_EQ(back.a.size(), n);
    ASSERT_EQ(back.b.size(), n);
    Eigen::VectorXd a = Eigen::VectorXd::Zero(n), b = Eigen::VectorXd::Zero(n);
    a.head(h.a.size()) = h.a / h.a(0);
    b.head(h.b.size()) = h.b / h.a(0);
    // Coefficients rebuilt from eigenvalues of small companion matrices: ~1e-15.
    EXPECT_LT((back.a - a).cwiseAbs().maxCoeff(), 1e-12) << "a: " << back.a.transpose();
    EXPECT_LT((back.b - b).cwiseAbs().maxCoeff(), 1e-12) << "b: " << back.b.transpose();

    // And the realisation runs the difference equation a * y = b * u.
    LtiFilter f(realize(h));
    std::vector<double> u(60), y(60);
    for (size_t k = 0; k < u.size(); ++k) u[k] = std::sin(0.3 * static_cast<double>(k)) + (k == 0 ? 1.0 : 0.0);
    for (size_t k = 0; k < u.size(); ++k) y[k] = f.step(u[k]);
    for (size_t k = 0; k < u.size(); ++k) {
      double lhs = 0.0, rhs = 0.0;
      for (Eigen::Index i = 0; i < a.size() && static_cast<size_t>(i) <= k; ++i) lhs += a(i) * y[k - static_cast<size_t>(i)];
      for (Eigen::Index i = 0; i < b.size() && static_cast<size_t>(i) <= k; ++i) rhs += b(i) * u[k - static_cast<size_t>(i)];
      EXPECT_NEAR(lhs, rhs, 1e-12) << "k=" << k;
    }
  }
}

TEST(DiscreteTransferFunction, DelaysZerosAndProducts) {
  DiscreteTransferFunction h{Eigen::Vector3d(0.0, 0.5, -0.25), Eigen::Vector2d(1.0, -0.5)};
  EXPECT_EQ(h.delay_samples(), 1);
  const auto z = h.zeros();
  ASSERT_EQ(z.size(), 1);
  EXPECT_NEAR(z(0).real(), 0.5, 1e-15);
  const auto p = h.poles();
  ASSERT_EQ(p.size(), 1);
  EXPECT_NEAR(p(0).real(), 0.5, 1e-15);
  EXPECT_DOUBLE_EQ(h.dc_gain(), 0.25 / 0.5);

  const auto d = h.delayed(2);
  EXPECT_EQ(d.delay_samples(), 3);
  EXPECT_EQ(d.b.size(), 5);
  EXPECT_NEAR(std::abs(d.frequency_response(7.0, 0.01) - h.frequency_response(7.0, 0.01) * std::polar(1.0, -0.14)), 0.0,
              1e-15);

  const auto hh = h * h;
  EXPECT_NEAR(std::abs(hh.frequency_response(3.0, 0.01) - std::pow(h.frequency_response(3.0, 0.01), 2)), 0.0, 1e-14);
  // Tolerance-based delay count ignores tiny leading coefficients.
  DiscreteTransferFunction tiny{Eigen::Vector3d(1e-15, 0.5, 0.1), Eigen::Vector2d(1.0, -0.5)};
  EXPECT_EQ(tiny.delay_samples(), 0);
  EXPECT_EQ(tiny.delay_samples(1e-12), 1);
}

}  // namespace
}  // namespace pvcgel::control
