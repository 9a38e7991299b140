#include "control/transfer_function.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>

#include "control/config_error.hpp"
#include "control/hammerstein_model.hpp"

namespace pvcgel::control {
namespace {

std::vector<double> sorted_real(const Eigen::VectorXcd& r) {
  std::vector<double> v;
  for (const auto& z : r) v.push_back(z.real());
  std::sort(v.begin(), v.end());
  return v;
}

TEST(TransferFunction, PaperGBasicProperties) {
  const TransferFunction G({1.15, 1.03}, {1.0, 17.11, 8.76});
  EXPECT_EQ(G.order(), 2);
  EXPECT_EQ(G.relative_degree(), 1);
  EXPECT_DOUBLE_EQ(G.dc_gain(), 1.03 / 8.76);
  EXPECT_TRUE(G.is_stable());
  EXPECT_TRUE(G.is_minimum_phase());

  // Poles: the roots of s^2 + 17.11 s + 8.76, both real.
  const double disc = std::sqrt(17.11 * 17.11 - 4.0 * 8.76);
  const auto p = G.poles();
  ASSERT_EQ(p.size(), 2);
  const auto pr = sorted_real(p);
  // Companion-matrix eigenvalues of a well-separated pair: ~1e-15 relative.
  EXPECT_NEAR(pr[0], (-17.11 - disc) / 2.0, 1e-12);
  EXPECT_NEAR(pr[1], (-17.11 + disc) / 2.0, 1e-12);
  EXPECT_NEAR(std::abs(p(0).imag()) + std::abs(p(1).imag()), 0.0, 1e-12);

  const auto z = G.zeros();
  ASSERT_EQ(z.size(), 1);
  EXPECT_NEAR(z(0).real(), -1.03 / 1.15, 1e-14);

  // G(jw) by hand.
  const std::complex<double> s(0.0, 3.0);
  const auto expected = (1.15 * s + 1.03) / (s * s + 17.11 * s + 8.76);
  EXPECT_NEAR(std::abs(G(s) - expected), 0.0, 1e-15);

  EXPECT_EQ(G.to_string(), "(1.15 s + 1.03) / (s^2 + 17.11 s + 8.76)");
  EXPECT_EQ(paper_model(2).G.num(), G.num());
  EXPECT_EQ(paper_model(2).G.den(), G.den());
}

TEST(TransferFunction, SlowestTimeConstantIsTheSlowestPolesAndZeroWithoutPoles) {
  // The paper's G: poles -0.5271 and -16.583 rad/s, so 1.897 s.
  const double disc = std::sqrt(17.11 * 17.11 - 4.0 * 8.76);
  EXPECT_NEAR(TransferFunction({1.15, 1.03}, {1.0, 17.11, 8.76}).slowest_time_constant_s(), 2.0 / (17.11 - disc), 1e-12);
  // A lightly damped pair: its envelope's time constant, 1 / (zeta w_n).
  EXPECT_NEAR(TransferFunction({1.0}, {1.0, 2.0, 101.0}).slowest_time_constant_s(), 1.0, 1e-12);
  EXPECT_EQ(TransferFunction({2.0}, {1.0}).slowest_time_constant_s(), 0.0);
}

TEST(TransferFunction, MinimumPhaseStabilityAndDegree) {
  EXPECT_FALSE(TransferFunction({-1.0, 1.0}, {1.0, 3.0, 2.0}).is_minimum_phase());  // zero at +1
  EXPECT_FALSE(TransferFunction({1.0, 0.0}, {1.0, 3.0, 2.0}).is_minimum_phase());   // zero at 0
  EXPECT_TRUE(TransferFunction({1.0}, {1.0, 3.0, 2.0}).is_minimum_phase());         // no zeros
  EXPECT_FALSE(TransferFunction({1.0}, {1.0, -1.0}).is_stable());
  EXPECT_FALSE(TransferFunction({1.0}, {1.0, 0.0}).is_stable());  // integrator: not strictly stable
  EXPECT_TRUE(TransferFunction({1.0}, {1.0, 0.5, 4.0}).is_stable());  // lightly damped complex pair

  const TransferFunction improper({1.0, 0.0, 0.0}, {1.0, 1.0});
  EXPECT_EQ(improper.relative_degree(), -1);
  // Leading zeros are stripped.
  const TransferFunction padded({0.0, 0.0, 2.0}, {0.0, 1.0, 1.0});
  EXPECT_EQ(padded.num().size(), 1u);
  EXPECT_EQ(padded.den().size(), 2u);
  EXPECT_EQ(padded.relative_degree(), 1);
}

TEST(TransferFunction, ProductAndInverse) {
  const TransferFunction a({1.0, 2.0}, {1.0, 3.0});
  const TransferFunction b({4.0}, {1.0, 5.0, 6.0});
  const auto ab = a * b;
  EXPECT_EQ(ab.num(), (std::vector<double>{4.0, 8.0}));
  EXPECT_EQ(ab.den(), (std::vector<double>{1.0, 8.0, 21.0, 18.0}));
  const auto inv = b.inverse();
  EXPECT_EQ(inv.num(), b.den());
  EXPECT_EQ(inv.den(), b.num());
  EXPECT_EQ(inv.relative_degree(), -2);
  const std::complex<double> s(0.3, 1.7);
  EXPECT_NEAR(std::abs(ab(s) - a(s) * b(s)), 0.0, 1e-14);
}

TEST(TransferFunction, RejectsBadCoefficientsWithKey) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const auto& [num, den] : std::vector<std::pair<std::vector<double>, std::vector<double>>>{
           {{1.0}, {}}, {{}, {1.0}}, {{nan}, {1.0, 1.0}}, {{1.0}, {1.0, std::numeric_limits<double>::infinity()}}, {{1.0}, {0.0, 0.0}}}) {
    try {
      TransferFunction g(num, den, "model.G");
      FAIL() << "bad transfer function accepted";
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), "model.G");
    }
  }
}

TEST(TransferFunction, PolynomialHelpers) {
  EXPECT_EQ(polynomial_multiply({1.0, 1.0}, {1.0, -1.0}), (std::vector<double>{1.0, 0.0, -1.0}));
  Eigen::VectorXcd roots(3);
  roots << -1.0, std::complex<double>(-2.0, 1.0), std::complex<double>(-2.0, -1.0);
  const auto p = polynomial_from_roots(roots);  // (s+1)(s^2+4s+5) = s^3 + 5 s^2 + 9 s + 5
  ASSERT_EQ(p.size(), 4u);
  const double expected[] = {1.0, 5.0, 9.0, 5.0};
  for (size_t i = 0; i < 4; ++i) EXPECT_NEAR(p[i], expected[i], 1e-14);
  const auto r = polynomial_roots(p);
  ASSERT_EQ(r.size(), 3);
  for (const auto& z : r) EXPECT_NEAR(std::abs((z + 1.0) * (z * z + 4.0 * z + 5.0)), 0.0, 1e-12);
}

}  // namespace
}  // namespace pvcgel::control
