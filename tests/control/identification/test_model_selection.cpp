#include "control/identification/model_selection.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace pvcgel::control::identification {
namespace {

PolynomialCandidate candidate(std::vector<double> c) {
  PolynomialCandidate p;
  p.terms = static_cast<int>(c.size());
  p.c = std::move(c);
  return p;
}

// n = 1 linear, n = 2 the paper's (monotone), n = 3 the paper's (turns over at 862 V).
NonlinearityFit paper_like_fit() {
  NonlinearityFit fit;
  fit.candidates = {candidate({0.2}), candidate({0.1270, 1.3057e-5}), candidate({0.0721, 2.1307e-5, -1.7231e-11})};
  fit.chosen_terms = 2;
  return fit;
}

std::vector<PredictionMetrics> nrmse(std::vector<double> v) {
  std::vector<PredictionMetrics> m(v.size());
  for (size_t i = 0; i < v.size(); ++i) m[i].nrmse = v[i];
  return m;
}

TEST(ModelSelection, PicksTheBestHeldOutPredictionAndLimitsTheVoltageBelowItsTurnover) {
  const auto choice = choose_by_validation(paper_like_fit(), {nrmse({0.9, 0.51, 0.007}), nrmse({0.8, 0.45, 0.009})},
                                           {.highest_bias_V = 500.0});
  EXPECT_EQ(choice.terms, 3);
  ASSERT_TRUE(choice.voltage_max_V.has_value());
  EXPECT_EQ(*choice.voltage_max_V, std::floor(0.98 * 862.0));  // the paper's n = 3 turns over at 862.0 V
  EXPECT_NEAR(choice.mean_nrmse[2], 0.008, 1e-12);
  EXPECT_NE(choice.rule.find("turns over at 862"), std::string::npos) << choice.rule;
}

TEST(ModelSelection, PrefersTheSmallerDegreeWithinTheParsimonyMargin) {
  const auto choice = choose_by_validation(paper_like_fit(), {nrmse({0.9, 0.0102, 0.0100})}, {.highest_bias_V = 500.0});
  EXPECT_EQ(choice.terms, 2);
  EXPECT_FALSE(choice.voltage_max_V.has_value());  // n = 2 is monotone on 0..1000 V
}

TEST(ModelSelection, ExcludesAnFThatTurnsOverBelowTheOperatingPoints) {
  const auto choice = choose_by_validation(paper_like_fit(), {nrmse({0.9, 0.51, 0.007})}, {.highest_bias_V = 900.0});
  EXPECT_EQ(choice.terms, 2);
  EXPECT_TRUE(std::isnan(choice.mean_nrmse[2]));
  EXPECT_NE(choice.rule.find("excluded"), std::string::npos) << choice.rule;
}

TEST(ModelSelection, RefusesWithoutValidationOrWithoutAnAdmissibleDegree) {
  EXPECT_THROW((void)choose_by_validation(paper_like_fit(), {}, {}), std::invalid_argument);
  NonlinearityFit falling;
  falling.candidates = {candidate({-0.1})};
  EXPECT_THROW((void)choose_by_validation(falling, {nrmse({0.1})}, {}), std::invalid_argument);
}

}  // namespace
}  // namespace pvcgel::control::identification
