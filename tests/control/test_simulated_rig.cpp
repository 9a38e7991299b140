#include "control/simulated_rig.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <vector>

#include "control/config_error.hpp"
#include "control/lti_filter.hpp"

namespace pvcgel::control {
namespace {

// A deterministic, varying voltage sequence within 0..1000 V.
double voltage_at(long k) { return 400.0 + 150.0 * std::sin(0.002 * static_cast<double>(k)) + 5.0 * std::sin(0.3 * static_cast<double>(k)); }

SimRigConfig ideal_config() { return SimRigConfig{}.exactly(paper_model(2)); }

TEST(SimulatedRig, SameSeedSameMeasurementsDifferentSeedDifferent) {
  SimRigConfig c;
  SimulatedRig a(c), b(c);
  c.seed = 2;
  SimulatedRig other(c);
  long differ = 0;
  const long n = 5000;
  for (long k = 0; k < n; ++k) {
    const double ya = a.measure(), yb = b.measure(), yo = other.measure();
    ASSERT_EQ(ya, yb) << "k=" << k;
    ASSERT_EQ(a.true_displacement_um(), b.true_displacement_um());
    if (yo != ya) ++differ;
    EXPECT_EQ(other.true_displacement_um(), a.true_displacement_um());  // only the noise differs
    a.apply(voltage_at(k));
    b.apply(voltage_at(k));
    other.apply(voltage_at(k));
  }
  // Two independent N(0, 0.05) draws quantised at 0.01 coincide with probability
  // ~ 0.01 / (sqrt(2) 0.05 sqrt(2 pi)) ~ 6%: far more than half must differ.
  EXPECT_GT(differ, n / 2);
}

TEST(SimulatedRig, NoiseHasTheConfiguredStandardDeviation) {
  SimulatedRig rig(SimRigConfig{});
  rig.reset_steady_state(300.0);
  const int n = 20000;
  double sum = 0.0, sum_sq = 0.0;
  for (int k = 0; k < n; ++k) {
    const double e = rig.measure() - rig.true_displacement_um();
    sum += e;
    sum_sq += e * e;
    rig.apply(300.0);
  }
  const double mean = sum / n;
  const double sd = std::sqrt(sum_sq / n - mean * mean);
  std::cout << "noise: mean " << mean << " um, std " << sd << " um over " << n << " samples\n";
  // Quantisation adds 0.01^2/12 to the variance (+0.2% in std); the sampling error of the std
  // is 1/sqrt(2n) = 0.5%: 5% is a 10-sigma bound.
  EXPECT_NEAR(sd, 0.05, 0.05 * 0.05);
  // Standard error of the mean is 0.05/sqrt(n) = 3.5e-4: 2e-3 is > 5 sigma.
  EXPECT_NEAR(mean, 0.0, 2e-3);
}

TEST(SimulatedRig, MeasurementsAreQuantised) {
  SimulatedRig rig(SimRigConfig{});
  bool any_off_grid_truth = false;
  for (long k = 0; k < 5000; ++k) {
    const double y = rig.measure();
    EXPECT_NEAR(y, std::round(y / 0.01) * 0.01, 1e-9) << "k=" << k;
    const double t = rig.true_displacement_um();
    if (std::abs(t - std::round(t / 0.01) * 0.01) > 1e-6) any_off_grid_truth = true;
    rig.apply(voltage_at(k));
  }
  EXPECT_TRUE(any_off_grid_truth);  // so the grid is the sensor's doing, not the plant's
}

TEST(SimulatedRig, VoltageStepReachesTheDisplacementAfterIoDelayPlusHold) {
  // Cycle convention: measure() is the displacement at the start of cycle k, apply(u) sets
  // cycle k's command and advances. With io_delay_samples = d the amplifier outputs u[k] during
  // cycle k + d, and the hold makes it visible in the displacement one cycle after that, i.e.
  // first after the apply() of cycle k + d.
  for (int d : {0, 1, 2, 3}) {
    SimRigConfig c;  // full paper rig: hysteresis, creep, n = 3 truth
    c.io_delay_samples = d;
    SimulatedRig stepped(c), held(c);
    stepped.reset_steady_state(300.0);
    held.reset_steady_state(300.0);
    const long k_step = 10;
    long first_change = -1;
    for (long k = 0; k < 30; ++k) {
      stepped.apply(k >= k_step ? 400.0 : 300.0);
      held.apply(300.0);
      if (first_change < 0 && stepped.true_displacement_um() != held.true_displacement_um()) first_change = k;
    }
    EXPECT_EQ(first_change, k_step + d) << "io_delay_samples=" << d;
    // Held at the steady state, nothing moves (reset_steady_state really is a rest point).
    SimulatedRig idle(c);
    idle.reset_steady_state(300.0);
    const double y0 = idle.true_displacement_um();
    for (int k = 0; k < 100; ++k) idle.apply(300.0);
    EXPECT_NEAR(idle.true_displacement_um(), y0, 1e-12 * std::abs(y0));
  }
}

TEST(SimulatedRig, IdealRigMatchesTheControllersDiscreteModel) {
  // With every non-ideal effect off and truth = model, measure() at cycle k equals the
  // controller's G_d (ZOH + one sample of I/O delay) driven by f(u): this is the timing
  // the disturbance observer and the feedforward are built on.
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, 1e-3, 1);
  SimulatedRig rig(ideal_config());
  LtiFilter gd(realize(plant.G_d));
  const double u0 = 350.0;
  rig.reset_steady_state(u0);
  gd.reset_steady_state(model.f(u0));
  double worst = 0.0, y_max = 0.0;
  for (long k = 0; k < 3000; ++k) {
    const double u = voltage_at(k) + (k > 1500 ? 100.0 : 0.0);
    const double y_rig = rig.measure();
    const double y_model = gd.step(model.f(u));
    worst = std::max(worst, std::abs(y_rig - y_model));
    y_max = std::max(y_max, std::abs(y_rig));
    rig.apply(u);
  }
  // Same ZOH model realised two ways (state space vs. transfer function). The TF's numerator
  // coefficients sum to ~1e-5 of their size (poles near z = 1), so its DC gain carries
  // ~1e-10 relative rounding; 1e-9 of the signal bounds that, and any timing error (a sample
  // early or late) would show up as ~1e-2 of it.
  EXPECT_LT(worst, 1e-9 * y_max);
}

TEST(SimulatedRig, SteadyStateIncludesCreepAndSaturatesAtTheTurnover) {
  SimRigConfig c = ideal_config();
  const double u = 300.0, w = c.truth.f(u), G0 = c.truth.G.dc_gain();
  SimulatedRig plain(c);
  plain.reset_steady_state(u);
  // (I - A) is ill-conditioned by the slow poles (~2e3 for G, ~2e4 for creep): 1e-10 relative.
  EXPECT_NEAR(plain.true_displacement_um(), G0 * w, 1e-10 * G0 * w);
  c.creep.enabled = true;
  SimulatedRig creeping(c);
  creeping.reset_steady_state(u);
  EXPECT_NEAR(creeping.true_displacement_um(), (1.0 + c.creep.fraction) * G0 * w, 1e-10 * G0 * w);

  SimulatedRig paper_rig(SimRigConfig{});  // n = 3 truth turns over near 862 V
  EXPECT_NEAR(paper_rig.saturation_voltage_V(), 862.0, 1.0);
  paper_rig.reset_steady_state(950.0);
  const double y950 = paper_rig.true_displacement_um();
  paper_rig.reset_steady_state(paper_rig.saturation_voltage_V());
  EXPECT_NEAR(y950, paper_rig.true_displacement_um(), 1e-9 * y950);  // held flat, not reversed
  EXPECT_EQ(SimulatedRig(ideal_config()).saturation_voltage_V(), 1000.0);
}

// (down-sweep minus up-sweep) displacement at 400 V on a slow 200 -> 600 -> 200 V triangle.
double sweep_gap_at_400V(const SimRigConfig& c) {
  SimulatedRig rig(c);
  rig.reset_steady_state(200.0);
  double up = 0.0, down = 0.0;
  for (int k = 0; k <= 40000; ++k) {
    const double u = k <= 20000 ? 200.0 + 0.02 * k : 600.0 - 0.02 * (k - 20000);
    rig.apply(u);
    if (k == 10000) up = rig.true_displacement_um();
    if (k == 30000) down = rig.true_displacement_um();
  }
  return down - up;
}

TEST(SimulatedRig, HysteresisMakesUpAndDownSweepsDiffer) {
  SimRigConfig c = ideal_config();
  const double dynamic_gap = sweep_gap_at_400V(c);  // G's own lag on the ramp, same in both
  c.hysteresis.enabled = true;
  const double gap = sweep_gap_at_400V(c) - dynamic_gap;
  // After 170+ V of travel the Bouc-Wen state is saturated (e^{-170/30} < 0.4%), so the
  // effective voltage is u -+ alpha h_sat = u -+ 1.5 V: the sweeps are 3 V apart in x.
  const double expected = c.truth.G.dc_gain() * (c.truth.f(401.5) - c.truth.f(398.5));
  std::cout << "hysteresis gap at 400 V: " << gap << " um (static prediction " << expected << " um)\n";
  // 10%: the unsaturated remainder of h and the slight change of G's ramp lag with f'(x).
  EXPECT_NEAR(gap, expected, 0.1 * expected);
}

TEST(SimulatedRig, AWanderingDriftIsARandomWalkOfTheDiagnosedSizeRestartedByAReset) {
  // wander 0.3 um/sqrt(s): the change over 1 s has an RMS of 0.3 um, over 4 s of 0.6 um.
  SimRigConfig c = SimRigConfig{}.exactly(paper_model(2));
  c.added_effects = {Effect{EffectKind::drift, {0.0, 0.0, 0.0, 0.0, 0.3}}};
  SimulatedRig rig(c);
  rig.reset_steady_state(300.0);
  const double rest_um = rig.true_displacement_um();
  std::vector<double> y;
  for (int k = 0; k < 400000; ++k) {  // 400 s at a constant voltage: the plant rests, the drift moves
    if (k % 1000 == 0) y.push_back(rig.true_displacement_um());
    rig.apply(300.0);
  }
  for (size_t lag : {1u, 4u}) {
    double sum = 0.0;
    for (size_t i = lag; i < y.size(); i += lag) sum += (y[i] - y[i - lag]) * (y[i] - y[i - lag]);
    const double rms = std::sqrt(sum / static_cast<double>(y.size() / lag - 1));
    // 400 and 100 independent increments: the RMS is within 8% and 15% (one standard error), 25% here.
    EXPECT_NEAR(rms, 0.3 * std::sqrt(static_cast<double>(lag)), 0.25 * 0.3 * std::sqrt(static_cast<double>(lag)))
        << "over " << lag << " s";
  }
  EXPECT_GT(std::abs(rig.true_displacement_um() - rest_um), 0.0);
  rig.reset_steady_state(300.0);
  EXPECT_DOUBLE_EQ(rig.true_displacement_um(), rest_um);  // a reset starts the drift's clock and walk again
  // Without wander the same drift holds still.
  c.added_effects[0].p[kDriftWander] = 0.0;
  SimulatedRig still(c);
  still.reset_steady_state(300.0);
  for (int k = 0; k < 5000; ++k) still.apply(300.0);
  EXPECT_NEAR(still.true_displacement_um(), rest_um, 1e-9);
}

TEST(SimulatedRig, RejectsBadConfigurationNamingTheKey) {
  auto expect_key = [](SimRigConfig c, const std::string& key) {
    try {
      SimulatedRig rig(c);
      ADD_FAILURE() << key << " accepted";
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), key) << e.what();
    }
  };
  SimRigConfig c;
  c.sample_time_s = 0.0;
  expect_key(c, "sim.sample_time_s");
  c = SimRigConfig{};
  c.io_delay_samples = 16;
  expect_key(c, "sim.io_delay_samples");
  c = SimRigConfig{};
  c.noise_sigma_um = -1.0;
  expect_key(c, "sim.noise_sigma_um");
  c = SimRigConfig{};
  c.quantization_um = std::nan("");
  expect_key(c, "sim.quantization_um");
  c = SimRigConfig{};
  c.hysteresis.saturation_V = 0.0;
  expect_key(c, "sim.hysteresis");
  c = SimRigConfig{};
  c.creep.time_constant_s = -1.0;
  expect_key(c, "sim.creep");
  c = SimRigConfig{};
  c.truth.G = TransferFunction({1.0}, {1.0, -2.0});
  expect_key(c, "sim.truth.G");
}

}  // namespace
}  // namespace pvcgel::control
