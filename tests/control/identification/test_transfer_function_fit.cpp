#include "control/identification/transfer_function_fit.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "control/hammerstein_model.hpp"
#include "control/identification/excitation_plan.hpp"

#include "support/frequency_response_data.hpp"

namespace pvcgel::control::identification {
namespace {

TEST(IdentTransferFunctionFit, RecoversAKnownGFromExactData) {
  const auto G = paper_model(2).G;
  const auto f = log_spaced(0.1, 10.0, 7);
  const auto [w, H] = test::exact_response(G, f);
  const auto fit = fit_transfer_function(w, H);
  const auto p = test::sorted_roots(fit.poles), pt = test::sorted_roots(G.poles());
  ASSERT_EQ(p.size(), 2u);
  for (size_t i = 0; i < 2; ++i) EXPECT_LT(std::abs(p[i] - pt[i]) / std::abs(pt[i]), 1e-6) << p[i] << " vs " << pt[i];
  ASSERT_EQ(fit.zeros.size(), 1);
  EXPECT_LT(std::abs(fit.zeros(0) - G.zeros()(0)) / std::abs(G.zeros()(0)), 1e-6);
  EXPECT_NEAR(fit.G.dc_gain(), G.dc_gain(), 1e-6 * G.dc_gain());
  EXPECT_GT(fit.fit_percent, 99.9999);
  EXPECT_TRUE(fit.stable);
  EXPECT_TRUE(fit.minimum_phase);
  EXPECT_TRUE(fit.control_problem().empty());
}

TEST(IdentTransferFunctionFit, RecoversOtherOrders) {
  const TransferFunction G({2.0, 6.0, 40.0}, {1.0, 9.0, 60.0, 80.0});  // third order, two zeros
  Eigen::VectorXd w = Eigen::VectorXd::LinSpaced(20, -1.0, 2.0);
  w = Eigen::pow(10.0, w.array()).matrix();
  Eigen::VectorXcd H(w.size());
  for (Eigen::Index k = 0; k < w.size(); ++k) H(k) = G({0.0, w(k)});
  TransferFunctionFitOptions o;
  o.numerator_order = 2;
  o.denominator_order = 3;
  const auto fit = fit_transfer_function(w, H, o);
  for (size_t i = 0; i < G.den().size(); ++i) EXPECT_NEAR(fit.G.den()[i], G.den()[i], 1e-6 * std::abs(G.den()[i]));
  for (size_t i = 0; i < G.num().size(); ++i) EXPECT_NEAR(fit.G.num()[i], G.num()[i], 1e-6 * std::abs(G.num()[i]));
}

TEST(IdentTransferFunctionFit, RefusesNonMinimumPhaseForControl) {
  const TransferFunction G({-1.15, 1.03}, {1.0, 17.11, 8.76});  // zero at s = +0.9
  const auto f = log_spaced(0.1, 10.0, 7);
  const auto [w, H] = test::exact_response(G, f);
  const auto fit = fit_transfer_function(w, H);
  EXPECT_TRUE(fit.stable);
  EXPECT_FALSE(fit.minimum_phase);
  EXPECT_NE(fit.control_problem().find("non-minimum phase"), std::string::npos) << fit.control_problem();
}

TEST(IdentTransferFunctionFit, RefusesTooFewPoints) {
  Eigen::VectorXd w(1);
  w << 1.0;
  Eigen::VectorXcd H(1);
  H << std::complex<double>(0.1, -0.1);
  EXPECT_THROW((void)fit_transfer_function(w, H), std::invalid_argument);
}

}  // namespace
}  // namespace pvcgel::control::identification
