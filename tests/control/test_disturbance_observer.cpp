#include "control/disturbance_observer.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <limits>
#include <numbers>
#include <vector>

#include "control/config_error.hpp"

namespace pvcgel::control {
namespace {

constexpr double kTs = 1e-3;
constexpr double kLambda = 0.1;

struct OpenLoop {
  std::vector<double> d_hat, d;
};

// Nominal discrete plant G_d (ZOH + 1 sample I/O delay) driven by v + d; the DOB sees y and v.
OpenLoop run_open_loop(double duration_s, double (*v_of_t)(double), double d_step, double t_step) {
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, kTs, 1);
  DisturbanceObserver dob(model, plant, kLambda);
  LtiFilter g(realize(plant.G_d));
  OpenLoop r;
  const long n = std::lround(duration_s / kTs);
  for (long k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * kTs;
    const double v = v_of_t(t);
    const double d = t >= t_step ? d_step : 0.0;
    const double y = g.peek(0.0);  // y[k] does not depend on u[k] (two samples of delay)
    r.d_hat.push_back(dob.estimate(y));
    dob.commit(v);
    g.step(v + d);
    r.d.push_back(d);
  }
  return r;
}

TEST(DisturbanceObserver, StepDisturbanceIsEstimatedWithTimeConstantLambda) {
  const double t_step = 1.0, D = 50.0;
  const auto r = run_open_loop(3.0, [](double) { return 0.0; }, D, t_step);
  const long k_step = std::lround(t_step / kTs);
  // Nothing before the disturbance.
  for (long k = 0; k < k_step; ++k) ASSERT_EQ(r.d_hat[static_cast<size_t>(k)], 0.0) << k;
  // Estimate = Q z^-2 d with Q = 1 / (lambda s + 1): 63.2% after 2 samples + lambda.
  long k63 = -1;
  for (long k = k_step; k < static_cast<long>(r.d_hat.size()); ++k) {
    if (r.d_hat[static_cast<size_t>(k)] >= (1.0 - std::exp(-1.0)) * D) {
      k63 = k;
      break;
    }
  }
  ASSERT_GE(k63, 0);
  const double t63 = static_cast<double>(k63 - k_step) * kTs;
  const double expected = kLambda + 2 * kTs;
  std::cout << "d_hat reached 63% after " << t63 << " s (lambda + 2 samples = " << expected << " s)\n";
  // The Tustin Q is within half a sample of the continuous one: 15% of lambda is generous
  // yet a wrong lambda, a missing/extra order of Q or a delay of 15 samples would fail.
  EXPECT_NEAR(t63, expected, 0.15 * kLambda);
  // Two samples of delay: still zero right after the step.
  EXPECT_EQ(r.d_hat[static_cast<size_t>(k_step + 1)], 0.0);
  EXPECT_GT(r.d_hat[static_cast<size_t>(k_step + 2)], 0.0);
  // Converged after 2 s = 20 lambda: e^-20 ~ 2e-9 of the step remains.
  EXPECT_NEAR(r.d_hat.back(), D, 1e-3 * D);
  // Never overshoots (first-order Q).
  for (double dh : r.d_hat) EXPECT_LE(dh, D * (1.0 + 1e-9));
}

TEST(DisturbanceObserver, KnownInputCancelsExactly) {
  // With a large, varying applied input and no disturbance, the estimate stays zero: the
  // input path Q z^-r must line up with the output path Q G^-1 sample for sample.
  const auto r = run_open_loop(3.0, [](double t) { return 300.0 + 80.0 * std::sin(2.0 * std::numbers::pi * 2.0 * t); },
                               0.0, 1e9);
  double worst = 0.0;
  for (double dh : r.d_hat) worst = std::max(worst, std::abs(dh));
  // Inputs O(400): exact cancellation up to rounding through two stable 3rd-order filters.
  EXPECT_LT(worst, 1e-8 * 400.0);
}

TEST(DisturbanceObserver, DisturbanceUnderVaryingInput) {
  const auto r = run_open_loop(4.0, [](double t) { return 300.0 + 80.0 * std::sin(2.0 * std::numbers::pi * 2.0 * t); },
                               -20.0, 1.0);
  EXPECT_NEAR(r.d_hat.back(), -20.0, 1e-3 * 20.0);  // 3 s = 30 lambda after the step
}

TEST(DisturbanceObserver, SteadyStateResetGivesZeroEstimate) {
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, kTs, 1);
  DisturbanceObserver dob(model, plant, kLambda);
  const double v0 = 400.0, y0 = v0 * model.G.dc_gain();
  dob.reset_steady_state(v0, model.G.dc_gain());
  for (int k = 0; k < 100; ++k) {
    EXPECT_NEAR(dob.estimate(y0), 0.0, 1e-9 * v0);
    EXPECT_NEAR(dob.filtered_input(), v0, 1e-9 * v0);
    dob.commit(v0);
  }
  // sum(a) = 1 - 0.990 cancels: rounding is amplified ~100x over eps.
  EXPECT_NEAR(dob.q().dc_gain(), 1.0, 1e-12);
  EXPECT_EQ(dob.q_g_inverse().relative_degree(), 0);  // Q (1st order) G^-1 (relative degree -1)
  EXPECT_TRUE(dob.q_g_inverse().is_stable());
}

TEST(DisturbanceObserver, RejectsBadParametersNamingTheKey) {
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, kTs, 1);
  for (double lambda : {0.0, -0.1, std::nan(""), std::numeric_limits<double>::infinity()}) {
    try {
      DisturbanceObserver dob(model, plant, lambda);
      FAIL() << lambda;
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), "controller.dob.lambda_s");
    }
  }
  for (int q : {0, 5}) {
    try {
      DisturbanceObserver dob(model, plant, kLambda, q);
      FAIL() << q;
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), "controller.dob.q_order");
    }
  }
  // Relative degree 2 needs Q of order >= 2.
  const HammersteinModel rd2{model.f, TransferFunction({1.0}, {1.0, 3.0, 2.0})};
  const auto plant2 = DiscretePlantModel::make(rd2.G, kTs, 1);
  try {
    DisturbanceObserver dob(rd2, plant2, kLambda, 1);
    FAIL() << "improper Q G^-1 accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "controller.dob.q_order");
    EXPECT_NE(std::string(e.what()).find("improper"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(DisturbanceObserver(rd2, plant2, kLambda, 2));
}

}  // namespace
}  // namespace pvcgel::control
