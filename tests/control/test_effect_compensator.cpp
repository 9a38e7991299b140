#include "control/effect_compensator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "control/config_error.hpp"
#include "control/controller.hpp"

namespace pvcgel::control {
namespace {

/// A random voltage history with many reversals of every size (small wiggles
/// inside the smallest play, large swings past the largest).
std::vector<double> random_history(std::uint64_t seed, int n) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> step(-1.0, 1.0), scale(0.0, 1.0);
  std::vector<double> u{500.0};
  double direction = 1.0;
  while (static_cast<int>(u.size()) < n) {
    if (scale(rng) < 0.05) direction = -direction;  // a reversal
    const double size = std::pow(10.0, 3.0 * scale(rng) - 1.0);  // 0.1 .. 100 V
    u.push_back(std::clamp(u.back() + direction * size * std::abs(step(rng)), 0.0, 1000.0));
  }
  return u;
}

TEST(HysteresisOperator, InverseUndoesForwardOverRandomHistoriesWithReversals) {
  // Every loop shape diagnose fits: narrow, wide, thresholds gathered (-0.85) or spread over decades (3),
  // and clockwise loops (alpha < 0: the output leads after a reversal).
  struct Case {
    double alpha, R, spread;
  };
  for (const auto& [alpha, R, spread] : std::vector<Case>{
           {0.05, 20.0, 0.0}, {0.3, 100.0, 0.0}, {0.85, 5.0, 0.0}, {0.6, 30.0, -0.85}, {0.89, 10.0, 3.0}, {0.4, 300.0, 1.5},
           {-0.1, 20.0, 0.0}, {-0.5, 50.0, 1.5}, {-0.3, 8.0, -0.85}}) {
    HysteresisOperator H(alpha, R, spread);
    H.reset(500.0);
    double worst_x = 0.0, worst_h = 0.0;
    for (double u : random_history(7, 20000)) {
      const double h = H.forward(u);
      worst_x = std::max(worst_x, std::abs(H.inverse(h) - u));        // inverse(forward(u)) == u
      worst_h = std::max(worst_h, std::abs(H.forward(H.inverse(h)) - h));
      H.commit(u);
    }
    EXPECT_LT(worst_x, 1e-9) << "alpha " << alpha << ", R " << R << ", spread " << spread;
    EXPECT_LT(worst_h, 1e-9) << "alpha " << alpha << ", R " << R << ", spread " << spread;
  }
}

TEST(HysteresisOperator, IsTheOperatorAugmentedPlantRuns) {
  // f(x) = x and a G that settles within one sample: the plant's output is its hysteresis operator.
  const HammersteinModel unit{OddPolynomial({1.0}), TransferFunction({1.0}, {1e-6, 1.0})};
  const Effect e{EffectKind::hysteresis, {0.2, 40.0, 1.2}};
  AugmentedPlant plant(unit, 0.0, 1e-3, e);
  HysteresisOperator H(0.2, 40.0, 1.2);
  plant.reset_steady_state(300.0);
  H.reset(300.0);
  double worst = 0.0;
  for (double u : random_history(3, 5000)) {
    const double expected = H.forward(u);
    H.commit(u);
    plant.apply(u);
    worst = std::max(worst, std::abs(plant.output() - expected));
  }
  EXPECT_LT(worst, 1e-9);
}

EffectCompensator compensator(std::vector<Effect> effects, double vmax = 1000.0) {
  return EffectCompensator(paper_model(2), effects, 1e-3, 0.0, vmax, 1, 100.0);
}

TEST(EffectCompensator, InputSideInversesAreExactAloneAndInMixtures) {
  const Effect hysteresis{EffectKind::hysteresis, {0.1, 30.0}}, dead_zone{EffectKind::dead_zone, {20.0, 30.0}},
      slew{EffectKind::slew_limit, {20000.0}};
  for (const auto& mix : std::vector<std::vector<Effect>>{
           {hysteresis}, {dead_zone}, {slew}, {hysteresis, dead_zone}, {slew, hysteresis}, {dead_zone, slew}}) {
    auto c = compensator(mix);
    c.reset_steady_state(400.0);
    double worst = 0.0;
    for (double u : random_history(11, 5000)) {
      // A target the effects can reach this cycle: what some voltage near u gives.
      const double x = c.effective_input(u);
      const double back = c.voltage_for(x);
      worst = std::max(worst, std::abs(c.effective_input(back) - x));
      c.commit(back, 0.0);
    }
    EXPECT_LT(worst, 1e-9) << to_string(mix.front().kind) << " + " << to_string(mix.back().kind);
  }
}

TEST(EffectCompensator, SlewLimitOutOfReachGivesTheLargestReachableStep) {
  auto c = compensator({{EffectKind::slew_limit, {10000.0}}});  // 10 V per sample
  c.reset_steady_state(100.0);
  const double u = c.voltage_for(200.0);
  EXPECT_NEAR(u, 110.0, 1e-12);
  EXPECT_NEAR(c.effective_input(u), 105.0, 1e-12);  // the mean of a full-rate ramp
}

TEST(EffectCompensator, DigitalSlewLimitInvertsWithinReachAndClampsBeyond) {
  auto c = compensator({{EffectKind::slew_limit, {10000.0, 1.0}}});  // 10 V per sample, on the held command
  c.reset_steady_state(100.0);
  EXPECT_NEAR(c.effective_input(c.voltage_for(104.0)), 104.0, 1e-12);
  c.reset_steady_state(100.0);
  const double u = c.voltage_for(200.0);
  EXPECT_NEAR(u, 110.0, 1e-12);
  EXPECT_NEAR(c.effective_input(u), 110.0, 1e-12);  // the whole step, held
}

/// f(x) = x, G settling within a microsecond.
const HammersteinModel kUnitModel{OddPolynomial({1.0}), TransferFunction({1.0}, {1e-6, 1.0})};

/// With kUnitModel the plant's output is the output-side effects of u. Runs 2 s of
/// a sine through plant and compensator; returns the largest error of linear_output against u, and leaves
/// the compensator at t = 2 s.
double worst_output_side_error(EffectCompensator& c, const std::vector<Effect>& effects) {
  AugmentedPlant plant(kUnitModel, 0.0, 1e-3, effects);
  plant.reset_steady_state(10.0);
  c.reset_steady_state(10.0);
  double worst = 0.0;
  for (int k = 0; k < 2000; ++k) {
    const double u = 50.0 + 40.0 * std::sin(0.01 * k);  // 10 .. 90 um: through a knee at 60
    plant.apply(u);
    c.commit(u, u);
    worst = std::max(worst, std::abs(c.linear_output(plant.output()) - u));
  }
  return worst;
}

TEST(EffectCompensator, OutputSideUndoesSaturationAndDrift) {
  const std::vector<Effect> effects{{EffectKind::saturation, {60.0, 50.0}}, {EffectKind::drift, {0.5, 0.2, 0.3}}};
  EffectCompensator c(kUnitModel, effects, 1e-3, 0.0, 1000.0, 0, 50.0);
  EXPECT_LT(worst_output_side_error(c, effects), 1e-9);
  // Preview: the drift 5 samples ahead is 5 samples of its rate further on.
  EXPECT_NEAR(c.linear_output(40.0, 5.0) - c.linear_output(40.0), -0.2 * 5e-3, 1e-12);
}

TEST(EffectCompensator, ASaturationOnTheDriveIsInvertedOnTheDriveAndLeavesTheOutputAlone) {
  // kUnitModel: G(0) = 1, so the drive's static displacement is w itself.
  const std::vector<Effect> effects{{EffectKind::saturation, {60.0, 50.0, 1.0}}};
  EffectCompensator c(kUnitModel, effects, 1e-3, 0.0, 1000.0, 0, 50.0);
  for (double w = -105.0; w <= 105.0; w += 0.5) {
    EXPECT_NEAR(c.drive(w), soft_saturation(w, effects[0].p), 1e-12) << w;
    EXPECT_NEAR(c.drive(c.drive_inverse(w)), w, 1e-9) << w;  // within 95% of the ceiling (110)
    EXPECT_EQ(c.linear_output(w), w);
  }
  // Beyond the ceiling the request is read as 95% of the way there, as on the output side.
  EXPECT_NEAR(c.drive(c.drive_inverse(500.0)), 60.0 + 0.95 * 50.0, 1e-9);
}

TEST(EffectCompensator, AnOffCentreSaturationIsUndoneAboutItsCentre) {
  // Centre -30 um: the knees lie at -70 and +10 um, so the sine (10 .. 90 um) runs past the upper one alone.
  const std::vector<Effect> effects{{EffectKind::saturation, {40.0, 50.0, 0.0, -30.0}}};
  EffectCompensator c(kUnitModel, effects, 1e-3, 0.0, 1000.0, 0, 50.0);
  EXPECT_LT(worst_output_side_error(c, effects), 1e-9);
  EXPECT_EQ(soft_saturation(-60.0, effects[0].p), -60.0);      // inside the lower knee
  EXPECT_GT(soft_saturation(-80.0, effects[0].p), -80.0 + 0.1);  // 10 um past it: pulled toward the centre
  EXPECT_LT(soft_saturation(60.0, effects[0].p), 60.0 - 10.0);  // 50 um past the upper knee
  EXPECT_NEAR(c.linear_output(soft_saturation(60.0, effects[0].p)), 60.0, 1e-9);
}

TEST(EffectCompensator, OutputSideUndoesASettlingDrift) {
  const std::vector<Effect> effects{{EffectKind::drift, {0.5, 0.2, 0.3, 0.8}}};
  EffectCompensator c(kUnitModel, effects, 1e-3, 0.0, 1000.0, 0, 50.0);
  EXPECT_LT(worst_output_side_error(c, effects), 1e-9);
  // Preview at t = 2 s, 1.7 s after the onset: the ramp has slowed to 0.2 exp(-1.7 / 0.8) um/s.
  const auto settled = [](double t) { return 0.5 + 0.2 * 0.8 * (1.0 - std::exp(-(t - 0.3) / 0.8)); };
  EXPECT_NEAR(c.linear_output(40.0, 5.0) - c.linear_output(40.0), -(settled(2.005) - settled(2.0)), 1e-12);
}

TEST(EffectCompensator, PredictsCreepAsPlantedWithItsDelay) {
  // f(x) = x, G settling within a sample, two samples of I/O delay: the plant's output is
  // u two samples ago plus creep (three branches); linear_output removes the creep.
  const HammersteinModel unit{OddPolynomial({1.0}), TransferFunction({1.0}, {1e-6, 1.0})};
  const std::vector<Effect> effects{{EffectKind::creep, {0.1, 0.05, 1.0}}};
  AugmentedPlant plant(unit, 2.0, 1e-3, effects);
  EffectCompensator c(unit, effects, 1e-3, 0.0, 1000.0, 2, 50.0);
  plant.reset_steady_state(30.0);
  c.reset_steady_state(30.0);
  c.reset_creep(30.0);
  std::vector<double> u{30.0, 30.0, 30.0};
  double worst = 0.0, creep_seen = 0.0;
  for (int k = 0; k < 3000; ++k) {
    u.push_back(50.0 + 20.0 * std::sin(0.02 * k) + (k % 500 < 250 ? 10.0 : -10.0));
    plant.apply(u.back());
    c.commit(u.back(), u.back());
    const double delayed = u[u.size() - 3];  // the input G has seen
    worst = std::max(worst, std::abs(c.linear_output(plant.output()) - delayed));
    creep_seen = std::max(creep_seen, std::abs(plant.output() - delayed));
  }
  EXPECT_GT(creep_seen, 1.0);
  EXPECT_LT(worst, 1e-6);
}

void expect_refused(const std::vector<Effect>& effects, const std::string& key, const std::string& words,
                    double vmax = 1000.0) {
  ControllerConfig cfg;
  cfg.effects = effects;
  cfg.voltage_max_V = vmax;
  try {
    Controller ctl(paper_model(2), cfg);
    ADD_FAILURE() << "accepted " << to_string(effects.front().kind);
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key().substr(0, key.size()), key) << e.what();
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

TEST(EffectCompensator, RefusesWhatCannotBeCompensatedSafelyWithTheReason) {
  expect_refused({{EffectKind::asymmetric_dynamics, {0.3}}}, "model.effect[0]", "cannot be compensated");
  expect_refused({{EffectKind::creep, {0.02, 5.0}}, {EffectKind::bias_dependent_dynamics, {0.3, 0.5}}},
                 "model.effect[1]", "time scale depends on the state");
  expect_refused({{EffectKind::hysteresis, {0.95, 30.0}}}, "model.effect[0].alpha", "sensor noise");
  expect_refused({{EffectKind::dead_zone, {500.0, 400.0}}}, "model.effect[0]", "voltage_max_V", 850.0);
  // The loop works around operating_point_um = 100 um: a knee at 20 um with 10 um softness is far below.
  expect_refused({{EffectKind::saturation, {20.0, 10.0}}}, "model.effect[0]", "beyond the knee");
  // Measured from an off-centre saturation's centre: 100 um is 90 um past a 40 um knee about -30 um.
  expect_refused({{EffectKind::saturation, {40.0, 15.0, 0.0, -30.0}}}, "model.effect[0]", "centre_um = -30");
  expect_refused({{EffectKind::delay, {0.02}}}, "model.effect[0]", "reference preview");
  expect_refused({{EffectKind::delay, {0.0125}}}, "model.effect[0]", "at most 8");
  // A full second-order mode in series: Q G^-1 is improper, G_d^-1 unstable; the design check names the effect.
  expect_refused({{EffectKind::resonance, {30.0, 0.2, 0.0}}}, "model.effect[0]", "folded into the linear model");
}

TEST(EffectCompensator, CompensableEffectsAreAccepted) {
  for (const auto& e : std::vector<Effect>{{EffectKind::hysteresis, {0.1, 30.0}},
                                           {EffectKind::creep, {0.05, 10.0}},
                                           {EffectKind::creep, {0.03, 3.0, 1.5}},
                                           {EffectKind::dead_zone, {20.0, 30.0}},
                                           {EffectKind::saturation, {100.0, 50.0}},
                                           {EffectKind::delay, {2.5e-3}},
                                           {EffectKind::slew_limit, {20000.0}},
                                           {EffectKind::drift, {0.1, 0.01, 1.0}},
                                           {EffectKind::resonance, {30.0, 0.2, 0.9}}}) {
    ControllerConfig cfg;
    cfg.effects = {e};
    EXPECT_NO_THROW(Controller(paper_model(2), cfg)) << to_string(e.kind);
  }
  ControllerConfig cfg;
  cfg.effects = {{EffectKind::delay, {2.5e-3}}};
  const Controller ctl(paper_model(2), cfg);
  EXPECT_EQ(ctl.preview_samples(), Controller(paper_model(2), ControllerConfig{}).preview_samples() + 3);
}

}  // namespace
}  // namespace pvcgel::control
