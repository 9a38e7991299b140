#include "control/inverse_correction.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <numbers>

#include "control/config_error.hpp"

namespace pvcgel::control {
namespace {

constexpr double kTs = 1e-3;
constexpr double kLearnSeconds = 60.0;

// Learns p on a noise-free nominal plant whose linear block actually receives p_true(f(u)).
InverseCorrection learn(const Eigen::Vector3d& theta_true, double seconds) {
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, kTs, 1);
  DisturbanceObserver dob(model, plant, 0.1);
  const double w_lo = model.f(0.0), w_hi = model.f(1000.0);
  InverseCorrection corr(dob, plant, w_lo, w_hi, 4.0);
  const double scale = w_hi;
  auto p_true = [&](double w) {
    const double z = w / scale;
    return scale * (theta_true(0) + z * (theta_true(1) + z * theta_true(2)));
  };
  LtiFilter g(realize(plant.G_d));
  const double u0 = 400.0, w0 = model.f(u0);
  dob.reset_steady_state(p_true(w0), model.G.dc_gain());
  corr.reset_steady_state(w0);
  g.reset_steady_state(p_true(w0));
  const long n = std::lround(seconds / kTs);
  for (long k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * kTs;
    const double y = g.peek(0.0);
    dob.estimate(y);
    corr.update(dob.filtered_input());
    const double u = u0 + 250.0 * std::sin(2.0 * std::numbers::pi * 0.5 * t) + 60.0 * std::sin(2.0 * std::numbers::pi * 3.1 * t);
    const double w = model.f(u);
    dob.commit(corr.forward(w));
    corr.commit(w);
    g.step(p_true(w));
  }
  return corr;
}

TEST(InverseCorrection, LearnsAGainMismatch) {
  const Eigen::Vector3d truth(0.0, 1.27, 0.0);
  const auto theta = learn(truth, kLearnSeconds).theta();
  std::cout << "learned theta " << theta.transpose() << "\n";
  // Noise-free, exact regression (both sides filtered by the same Q z^-r): the only error is
  // the forgotten prior [0, 1, 0], whose weight after 15 memory time constants is e^-15 = 3e-7
  // (after 5 it was still 3e-3 in the weakly excited z^2 direction).
  EXPECT_NEAR(theta(0), truth(0), 1e-5);
  EXPECT_NEAR(theta(1), truth(1), 1e-5);
  EXPECT_NEAR(theta(2), truth(2), 1e-5);
}

TEST(InverseCorrection, LearnsAQuadraticMismatch) {
  const Eigen::Vector3d truth(0.01, 1.1, 0.15);
  const auto theta = learn(truth, kLearnSeconds).theta();
  std::cout << "learned theta " << theta.transpose() << "\n";
  EXPECT_NEAR(theta(0), truth(0), 1e-5);  // as above
  EXPECT_NEAR(theta(1), truth(1), 1e-5);
  EXPECT_NEAR(theta(2), truth(2), 1e-5);
}

TEST(InverseCorrection, StartsAsIdentity) {
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, kTs, 1);
  DisturbanceObserver dob(model, plant, 0.1);
  InverseCorrection corr(dob, plant, model.f(0.0), model.f(1000.0), 4.0);
  EXPECT_EQ(corr.theta(), Eigen::Vector3d(0.0, 1.0, 0.0));
  EXPECT_NEAR(corr.forward(1234.5), 1234.5, 1e-9);
  EXPECT_NEAR(corr.inverse(1234.5), 1234.5, 1e-9);
}

TEST(InverseCorrection, InverseInvertsALearnedCurvedMap) {
  const auto corr = learn(Eigen::Vector3d(0.01, 1.1, 0.15), kLearnSeconds);
  ASSERT_GT(corr.theta()(2), 0.1);  // really curved
  const double w_hi = paper_model(2).f(1000.0);
  for (int i = 0; i <= 100; ++i) {
    const double w = w_hi * i / 100.0;
    // Closed-form quadratic root (citardauq form): a few ulps of the scale.
    EXPECT_NEAR(corr.inverse(corr.forward(w)), w, 1e-10 * w_hi) << w;
  }
}

TEST(InverseCorrection, RefusesNonMonotoneMaps) {
  // Truth p(z) = z - 0.8 z^2 turns over at z = 0.625 inside the range (z up to 1): the learner
  // must never adopt a map that is not increasing over the whole voltage range.
  const auto corr = learn(Eigen::Vector3d(0.0, 1.0, -0.8), kLearnSeconds);
  const auto& th = corr.theta();
  std::cout << "theta under a non-monotone truth: " << th.transpose() << "\n";
  const double z_hi = 1.0;  // w_upper / scale
  EXPECT_GT(th(1), 0.2);
  EXPECT_GT(th(1) + 2.0 * th(2) * 0.0, 0.0);
  EXPECT_GT(th(1) + 2.0 * th(2) * z_hi, 0.0);
}

TEST(InverseCorrection, RejectsAShortMemory) {
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, kTs, 1);
  DisturbanceObserver dob(model, plant, 0.1);
  try {
    InverseCorrection corr(dob, plant, 0.0, 1000.0, 5e-3);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "controller.feedforward.learning_memory_s");
  }
}

}  // namespace
}  // namespace pvcgel::control
