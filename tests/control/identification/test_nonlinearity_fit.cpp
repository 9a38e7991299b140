#include "control/identification/nonlinearity_fit.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "control/hammerstein_model.hpp"

namespace pvcgel::control::identification {
namespace {

DescribingFunctionData grid_of(const OddPolynomial& f) {
  DescribingFunctionData d;
  std::vector<double> A, B, g;
  for (double a : {300.0, 350.0, 400.0})
    for (double b : {400.0, 450.0, 500.0})
      for (int rep = 0; rep < 7; ++rep) {  // 7 frequencies: same (A, B), same N
        A.push_back(a);
        B.push_back(b);
        g.push_back(f.describing_function(a, b));
      }
  d.amplitude_V = Eigen::Map<Eigen::VectorXd>(A.data(), static_cast<Eigen::Index>(A.size()));
  d.bias_V = Eigen::Map<Eigen::VectorXd>(B.data(), static_cast<Eigen::Index>(B.size()));
  d.gain = Eigen::Map<Eigen::VectorXd>(g.data(), static_cast<Eigen::Index>(g.size()));
  return d;
}

TEST(IdentNonlinearityFit, RecoversPolynomialsOfDegreeOneToThreeFromExactData) {
  for (int n = 1; n <= 3; ++n) {
    const auto truth = paper_model(n).f;
    const auto cand = fit_odd_polynomial(n, grid_of(truth));
    ASSERT_EQ(cand.c.size(), static_cast<size_t>(n));
    for (int i = 1; i <= n; ++i)
      EXPECT_NEAR(cand.c[static_cast<size_t>(i - 1)], truth.coefficient(i), 1e-7 * std::abs(truth.coefficient(i)))
          << "n = " << n << ", c" << i;
    EXPECT_LT(cand.relative_residual, 1e-10);
  }
}

TEST(IdentNonlinearityFit, ResidualsFallWithDegreeAndTheRuleIsStated) {
  const auto d = grid_of(paper_model(2).f);
  NonlinearityFitOptions o;
  o.max_terms = 3;
  const auto fit = fit_nonlinearity(d, o);
  ASSERT_EQ(fit.candidates.size(), 3u);
  EXPECT_GT(fit.candidate(1).residual_norm, 1e3 * fit.candidate(2).residual_norm);
  EXPECT_LT(fit.candidate(3).relative_residual, 1e-12);  // exact data: both at round-off
  EXPECT_EQ(fit.chosen_terms, 2);  // n = 3 cannot do better than exact
  EXPECT_NE(fit.rule.find("within 10%"), std::string::npos) << fit.rule;
}

TEST(IdentNonlinearityFit, ExcludesPolynomialsThatTurnOverInTheVoltageRange) {
  // The paper's n = 3 fit turns over at 862 V: not admissible over 0..1000 V,
  // admissible when the controller is limited to 850 V.
  const auto d = grid_of(paper_model(3).f);
  NonlinearityFitOptions o;
  o.max_terms = 3;
  const auto fit = fit_nonlinearity(d, o);
  ASSERT_TRUE(fit.candidate(3).turnover_V.has_value());
  EXPECT_NEAR(*fit.candidate(3).turnover_V, 862.0, 1.0);
  EXPECT_EQ(fit.chosen_terms, 2);
  EXPECT_NE(fit.rule.find("n = 3 excluded: f turns over at 862"), std::string::npos) << fit.rule;
  o.voltage_max_V = 850.0;
  EXPECT_EQ(fit_nonlinearity(d, o).chosen_terms, 3);
  o.forced_terms = 1;
  EXPECT_EQ(fit_nonlinearity(d, o).chosen_terms, 1);
}

TEST(IdentNonlinearityFit, RefusesTooFewPoints) {
  DescribingFunctionData d;
  d.amplitude_V = Eigen::VectorXd::Constant(2, 300.0);
  d.bias_V = Eigen::VectorXd::Constant(2, 450.0);
  d.gain = Eigen::VectorXd::Constant(2, 1.0);
  EXPECT_THROW((void)fit_odd_polynomial(3, d), std::invalid_argument);
}

}  // namespace
}  // namespace pvcgel::control::identification
