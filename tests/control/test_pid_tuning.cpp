#include "control/pid_tuning.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <ostream>

#include "control/config_error.hpp"
#include "control/hammerstein_model.hpp"

namespace pvcgel::control {
namespace {

constexpr double kTs = 1e-3;
constexpr double kDeg = 180.0 / std::numbers::pi;

DiscreteTransferFunction paper_plant() {
  return DiscretePlantModel::make(paper_model(2).G, kTs, 1).G_d;
}

struct Target {
  double wc, pm;
};
void PrintTo(const Target& t, std::ostream* os) { *os << "crossover " << t.wc << " rad/s, PM " << t.pm << " deg"; }

class TunePid : public ::testing::TestWithParam<Target> {};

TEST_P(TunePid, MeetsCrossoverAndPhaseMarginOnThePaperPlant) {
  const auto [wc, pm] = GetParam();
  const auto plant = paper_plant();
  const TuningTarget target{wc, pm};
  const TuningResult r = tune_pid(plant, kTs, target);

  // At the target frequency exactly: |C P| = 1 and arg(C P) = -180 + PM (the design equations,
  // solved by 80 bisections on log Ti: far below 1e-6 deg).
  const auto L = pid_transfer_function(r.gains, kTs).frequency_response(wc, kTs) * plant.frequency_response(wc, kTs);
  EXPECT_NEAR(std::abs(L), 1.0, 1e-9);
  EXPECT_NEAR(std::arg(L) * kDeg, -180.0 + pm, 1e-6);

  // What loop_margins reads off its frequency grid (0.25% spacing): crossover within 2%,
  // phase margin within 1 degree, and the closed loop is stable.
  EXPECT_NEAR(r.margins.crossover_rad_s, wc, 0.02 * wc);
  EXPECT_NEAR(r.margins.phase_margin_deg, pm, 1.0);
  EXPECT_TRUE(r.margins.stable());
  EXPECT_LT(r.margins.max_closed_loop_pole_abs, 1.0);
  EXPECT_GT(r.margins.gain_margin_db, 0.0);

  // The gains belong to the documented family: Td = 0.25 Ti, tf = max(Td / 10, Ts).
  const double Ti = r.gains.kp / r.gains.ki, Td = r.gains.kd / r.gains.kp;
  EXPECT_GT(r.gains.kp, 0.0);
  EXPECT_NEAR(Td / Ti, target.derivative_ratio, 1e-12);
  EXPECT_NEAR(r.gains.tf_s, std::max(Td / target.derivative_filter_n, kTs), 1e-15);

  // Recomputing the margins from the gains gives the same answer (tuner and check agree).
  const auto m = loop_margins(pid_transfer_function(r.gains, kTs), plant, kTs);
  EXPECT_DOUBLE_EQ(m.crossover_rad_s, r.margins.crossover_rad_s);
  EXPECT_DOUBLE_EQ(m.phase_margin_deg, r.margins.phase_margin_deg);
}

INSTANTIATE_TEST_SUITE_P(Targets, TunePid, ::testing::Values(Target{30, 60}, Target{45, 60}, Target{100, 50}),
                         [](const auto& param_info) {
                           return "wc" + std::to_string(static_cast<int>(param_info.param.wc)) + "_pm" +
                                  std::to_string(static_cast<int>(param_info.param.pm));
                         });

TEST(TunePid, UnreachableTargetThrowsNamingTuning) {
  try {
    (void)tune_pid(paper_plant(), kTs, TuningTarget{1500.0, 80.0});
    FAIL() << "1500 rad/s with 80 deg accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "controller.tuning");
    EXPECT_NE(std::string(e.what()).find("controller.tuning"), std::string::npos);
  }
}

TEST(TunePid, OutOfRangeTargetsThrowNamingTheField) {
  try {
    (void)tune_pid(paper_plant(), kTs, TuningTarget{4000.0, 60.0});  // above Nyquist (3141.6 rad/s)
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "controller.tuning.crossover_rad_s");
  }
  for (double pm : {0.0, 90.0, -10.0, std::nan("")}) {
    try {
      (void)tune_pid(paper_plant(), kTs, TuningTarget{45.0, pm});
      FAIL() << pm;
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), "controller.tuning.phase_margin_deg");
    }
  }
}

TEST(LoopMargins, MatchAnalyticIntegratorLoop) {
  // C = k, P = Ts z^-1 / (1 - z^-1): |L(e^{jwTs})| = k Ts / (2 sin(w Ts / 2)), arg L = -90 - w Ts/2 (rad->deg).
  const double k = 50.0;
  const DiscreteTransferFunction C{Eigen::VectorXd::Constant(1, k), Eigen::VectorXd::Ones(1)};
  const DiscreteTransferFunction P{Eigen::Vector2d(0.0, kTs), Eigen::Vector2d(1.0, -1.0)};
  const auto m = loop_margins(C, P, kTs);
  const double wc = 2.0 / kTs * std::asin(k * kTs / 2.0);
  const double pm = 90.0 - wc * kTs / 2.0 * kDeg;
  EXPECT_NEAR(m.crossover_rad_s, wc, 0.005 * wc);  // grid spacing 0.25%: first point past crossover
  EXPECT_GE(m.crossover_rad_s, wc);
  EXPECT_NEAR(m.phase_margin_deg, pm, 0.05);        // phase changes ~0.007 deg across one grid step
  EXPECT_TRUE(std::isinf(m.gain_margin_db));        // phase only reaches -180 at Nyquist
  // Closed loop: 1 - z^-1 + k Ts z^-1 = 0 -> z = 1 - k Ts.
  EXPECT_NEAR(m.max_closed_loop_pole_abs, 1.0 - k * kTs, 1e-12);
  const auto poles = closed_loop_poles(C, P);
  ASSERT_EQ(poles.size(), 1);
  EXPECT_NEAR(poles(0).real(), 1.0 - k * kTs, 1e-12);

  // Large enough gain puts the pole outside the unit circle: 1 - k Ts < -1.
  const DiscreteTransferFunction C_big{Eigen::VectorXd::Constant(1, 2500.0), Eigen::VectorXd::Ones(1)};
  EXPECT_FALSE(loop_margins(C_big, P, kTs).stable());
}

TEST(LoopMargins, FiniteGainMarginWhenPhaseCrossesMinus180) {
  // C = k, P = z^-3 (pure delay): phase -3 w Ts reaches -180 deg at w = pi / (3 Ts).
  const double k = 0.5;
  const DiscreteTransferFunction C{Eigen::VectorXd::Constant(1, k), Eigen::VectorXd::Ones(1)};
  DiscreteTransferFunction P{Eigen::Vector4d(0.0, 0.0, 0.0, 1.0), Eigen::VectorXd::Ones(1)};
  const auto m = loop_margins(C, P, kTs);
  // |L| = 0.5 everywhere: gain margin 6.02 dB, read at the first grid point past -180 deg.
  EXPECT_NEAR(m.gain_margin_db, -20.0 * std::log10(k), 1e-9);
  EXPECT_TRUE(m.stable());
}

}  // namespace
}  // namespace pvcgel::control
