#include "control/effect.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "control/config_error.hpp"
#include "control/config/effect_config.hpp"
#include "control/simulated_rig.hpp"
#include "control/state_space.hpp"

namespace pvcgel::control::diagnosis {
namespace {

constexpr double Ts = 1e-3;

std::vector<double> voltage(size_t n) {
  std::vector<double> u(n);
  for (size_t k = 0; k < n; ++k)
    u[k] = 300.0 + 150.0 * std::sin(0.003 * static_cast<double>(k)) + 20.0 * std::sin(0.05 * static_cast<double>(k));
  return u;
}

std::vector<double> run(const Effect& e, const std::vector<double>& u, double initial_V) {
  AugmentedPlant p(paper_model(3), 1, Ts, e);
  return p.simulate(u, initial_V);
}

/// The paper's G (1.15 s + 1.03) / (s^2 + 17.11 s + 8.76) in modal form r1 / (s + p1) + r2 / (s + p2), p1 the
/// slow pole: the reference of the slow-pole-only forms.
struct PaperModes {
  double p1, p2, r1, r2;
};
PaperModes paper_modes(const HammersteinModel& model) {
  const auto poles = model.G.poles();
  const double p1 = -std::max(poles(0).real(), poles(1).real()), p2 = -std::min(poles(0).real(), poles(1).real());
  const auto residue = [&](double p, double other) { return (1.15 * -p + 1.03) / (-p + other); };
  return {p1, p2, residue(p1, p2), residue(p2, p1)};
}

/// 1 s at 0 V, 3 s at 600 V, 4 s at 200 V: a rise and a relaxation.
std::vector<double> up_and_down() {
  std::vector<double> u(8000, 0.0);
  for (size_t k = 0; k < u.size(); ++k) u[k] = k < 1000 ? 0.0 : k < 4000 ? 600.0 : 200.0;
  return u;
}

/// The reference of the slow-pole-only forms: G's modal form stepped exactly over each sample (ZOH) with the slow
/// mode N = clamp(1 + beta (y - centre) / y_ref, 0.25, 4) times slower, N held over the sample, the plant's
/// 1-sample I/O delay, y_op = y (time constant 0), at rest at 0 V first; with creep_fraction c not 0, plus a
/// creep branch c G(0) / (tau s + 1) in parallel, stepped with its own pole.
std::vector<double> slow_pole_reference(const HammersteinModel& model, const std::vector<double>& u, double beta,
                                        double y_ref, double centre, double creep_fraction = 0.0,
                                        double creep_tau_s = 1.0) {
  const auto [p1, p2, r1, r2] = paper_modes(model);
  const double a2 = std::exp(-p2 * Ts), a3 = std::exp(-Ts / creep_tau_s), creep_gain = creep_fraction * model.G.dc_gain();
  std::vector<double> y(u.size(), 0.0);
  double x1 = 0.0, x2 = 0.0, x3 = 0.0;
  for (size_t k = 1; k < u.size(); ++k) {
    const double w = model.f(k >= 2 ? u[k - 2] : 0.0);
    const double N = std::clamp(1.0 + beta * (y[k - 1] - centre) / y_ref, 0.25, 4.0);
    const double a1 = std::exp(-p1 * Ts / N);
    x1 = a1 * x1 + (1.0 - a1) * w / p1;
    x2 = a2 * x2 + (1.0 - a2) * w / p2;
    x3 = a3 * x3 + (1.0 - a3) * creep_gain * w;
    y[k] = r1 * x1 + r2 * x2 + x3;
  }
  return y;
}

std::vector<double> steps(size_t n, double from, double to) {
  std::vector<double> u(n, to);
  u[0] = from;
  return u;
}

/// The largest |y - reference| (infinite once y is not finite) and the largest |reference|.
struct Gap {
  double largest = 0.0, span = 0.0;
};
Gap gap_to(const std::vector<double>& y, const std::vector<double>& reference) {
  Gap g;
  for (size_t k = 0; k < y.size(); ++k) {
    const double d = std::abs(y[k] - reference[k]);
    g.largest = std::isfinite(d) ? std::max(g.largest, d) : INFINITY;
    g.span = std::max(g.span, std::abs(reference[k]));
  }
  return g;
}

TEST(AugmentedPlant, NominalIsExactlyTheSimulatedRigWithoutSensorEffects) {
  const SimRigConfig c = SimRigConfig{}.exactly(paper_model(3));
  SimulatedRig rig(c);
  const auto u = voltage(5000);
  rig.reset_steady_state(u[0]);
  const auto y = run({}, u, u[0]);
  for (size_t k = 0; k < u.size(); ++k) {
    ASSERT_NEAR(y[k], rig.true_displacement_um(), 1e-9) << "k=" << k;
    rig.apply(u[k]);
  }
}

TEST(AugmentedPlant, HysteresisMakesTheFallingBranchHigherThanTheRisingOne) {
  // Slow triangle 100 -> 500 -> 100 V: compare y at 300 V on the way up and down.
  std::vector<double> u;
  for (int k = 0; k <= 40000; ++k) u.push_back(100.0 + 400.0 * (k <= 20000 ? k : 40000 - k) / 20000.0);
  const auto y0 = run({}, u, u[0]);
  const auto y = run({EffectKind::hysteresis, {0.05, 20.0}}, u, u[0]);
  const double up = y[10000] - y0[10000], down = y[30000] - y0[30000];
  EXPECT_LT(up, -0.1);   // the effective voltage lags below u while rising
  EXPECT_GT(down, 0.1);  // and above it while falling
  const auto none = run({EffectKind::hysteresis, {0.0, 20.0}}, u, u[0]);
  EXPECT_NEAR(none[30000], y0[30000], 1e-12);
}

TEST(AugmentedPlant, ALoopStartingOnABranchIsTheStateReachedAlongIt) {
  // f(x) = x and a G that settles within one sample: the output is the effective voltage. A plant that
  // rests at 300 V on its rising (falling) branch must be the plant that came up (down) to 300 V from
  // beyond its widest play, and then follow the same loop.
  const HammersteinModel unit{OddPolynomial({1.0}), TransferFunction({1.0}, {1e-6, 1.0})};
  for (double alpha : {0.3, -0.3}) {
    const Effect e{EffectKind::hysteresis, {alpha, 20.0, 1.0}};
    for (double branch : {1.0, -1.0}) {
      AugmentedPlant travelled(unit, 0.0, Ts, e), started(unit, 0.0, Ts, e);
      travelled.reset_steady_state(300.0 - branch * 400.0);
      for (int k = 0; k <= 400; ++k) travelled.apply(300.0 - branch * 400.0 + branch * k);
      for (int k = 0; k < 5; ++k) travelled.apply(300.0);
      started.set_loop_memory(branch);
      started.reset_steady_state(300.0);
      started.apply(300.0);
      EXPECT_NEAR(started.output(), travelled.output(), 1e-9) << "alpha " << alpha << ", branch " << branch;
      double worst = 0.0;
      for (double u : voltage(3000)) {
        travelled.apply(u);
        started.apply(u);
        worst = std::max(worst, std::abs(started.output() - travelled.output()));
      }
      EXPECT_LT(worst, 1e-9) << "alpha " << alpha << ", branch " << branch;
    }
    AugmentedPlant virgin(unit, 0.0, Ts, e), rising(unit, 0.0, Ts, e);
    virgin.reset_steady_state(300.0);
    rising.set_loop_memory(1.0);
    rising.reset_steady_state(300.0);
    // Rising branch: the plays trail below the input, so the loop lowers (alpha > 0) the effective voltage.
    EXPECT_LT(alpha * (rising.output() - virgin.output()), -1.0) << "alpha " << alpha;
  }
}

TEST(AugmentedPlant, ALoopStartingPartwayIsTheVirginLoopAfterOneStepOfThatShareOfTheWidestPlay) {
  // A recording that starts after a hold at another level: the virgin loop at 300 - step, then one step to
  // 300 V. With the plays' widths spread, a step of a third of the widest play leaves the narrow plays on
  // the branch and the wide ones displaced by the step.
  const HammersteinModel unit{OddPolynomial({1.0}), TransferFunction({1.0}, {1e-6, 1.0})};
  const Effect e{EffectKind::hysteresis, {0.3, 20.0, 1.0}};
  const double widest = AugmentedPlant(unit, 0.0, Ts, e).widest_play_V();
  for (double share : {1.0 / 3.0, -0.6}) {
    AugmentedPlant stepped(unit, 0.0, Ts, e), started(unit, 0.0, Ts, e), full(unit, 0.0, Ts, e);
    stepped.reset_steady_state(300.0 - share * widest);
    stepped.apply(300.0);
    stepped.apply(300.0);
    started.set_loop_memory(share);
    started.reset_steady_state(300.0);
    started.apply(300.0);
    EXPECT_NEAR(started.output(), stepped.output(), 1e-9) << share;
    full.set_loop_memory(share > 0.0 ? 1.0 : -1.0);
    full.reset_steady_state(300.0);
    full.apply(300.0);
    EXPECT_GT(std::abs(full.output() - started.output()), 1e-3) << "partway is not the whole branch";
    double worst = 0.0;
    for (double u : voltage(3000)) {
      stepped.apply(u);
      started.apply(u);
      worst = std::max(worst, std::abs(started.output() - stepped.output()));
    }
    EXPECT_LT(worst, 1e-9) << share;
  }
}

TEST(AugmentedPlant, CreepAddsASlowFirstOrderBranch) {
  const double tau = 5.0, fraction = 0.02;
  const auto u = steps(60000, 200.0, 400.0);
  const auto y0 = run({}, u, 200.0);
  const auto y = run({EffectKind::creep, {fraction, tau}}, u, 200.0);
  const auto model = paper_model(3);
  const double g0 = model.G.dc_gain();
  EXPECT_NEAR(y[0] - y0[0], fraction * g0 * model.f(200.0), 1e-9);  // at rest, the branch is charged
  EXPECT_NEAR(y.back() - y0.back(), fraction * g0 * model.f(400.0), 1e-3);
  // After one tau, 1 - e^-1 of the branch's step is done.
  const double step = fraction * g0 * (model.f(400.0) - model.f(200.0));
  const double done = (y[5000] - y0[5000] - fraction * g0 * model.f(200.0)) / step;
  EXPECT_NEAR(done, 1.0 - std::exp(-1.0), 0.02);
}

TEST(AugmentedPlant, DeadZoneHasNoResponseBelowTheThresholdAndNominalAboveTwice) {
  const Effect e{EffectKind::dead_zone, {30.0, 30.0}};
  EXPECT_NEAR(run(e, steps(20000, 0.0, 25.0), 0.0).back(), 0.0, 1e-12);
  EXPECT_NEAR(run(e, steps(20000, 0.0, 80.0), 0.0).back(), run({}, steps(20000, 0.0, 80.0), 0.0).back(), 1e-6);
  EXPECT_LT(run(e, steps(20000, 0.0, 45.0), 0.0).back(), run({}, steps(20000, 0.0, 45.0), 0.0).back());
}

TEST(AugmentedPlant, SaturationSoftensAboveTheKnee) {
  const Effect e{EffectKind::saturation, {100.0, 200.0}};
  const auto u = steps(30000, 0.0, 600.0);
  const double nominal = run({}, u, 0.0).back();
  ASSERT_GT(nominal, 100.0);
  const double excess = nominal - 100.0;
  EXPECT_NEAR(run(e, u, 0.0).back(), 100.0 + excess / std::sqrt(1.0 + (excess / 200.0) * (excess / 200.0)), 1e-6);
  EXPECT_NEAR(run(e, steps(30000, 0.0, 150.0), 0.0).back(), run({}, steps(30000, 0.0, 150.0), 0.0).back(), 1e-9);
}

TEST(AugmentedPlant, SaturationOnTheDriveIsGFedTheSaturatedDrive) {
  const Effect on_drive{EffectKind::saturation, {100.0, 200.0, 1.0}}, on_output{EffectKind::saturation, {100.0, 200.0}};
  const auto model = paper_model(3);
  const double dc = model.G.dc_gain();
  // The voltage whose f gives the saturated drive of 600 V: the nominal plant stepped there is the same plant.
  const double w = soft_saturation(dc * model.f(600.0), {100.0, 200.0, 0.0, 0.0}) / dc;
  double lo = 0.0, hi = 600.0;
  for (int i = 0; i < 100; ++i) (model.f(0.5 * (lo + hi)) < w ? lo : hi) = 0.5 * (lo + hi);
  const auto saturated = run(on_drive, steps(30000, 0.0, 600.0), 0.0);
  const auto equivalent = run({}, steps(30000, 0.0, 0.5 * (lo + hi)), 0.0);
  for (size_t k = 0; k < saturated.size(); k += 100) ASSERT_NEAR(saturated[k], equivalent[k], 1e-9) << k;
  // At rest both placements give the same displacement; on the way there, the drive's lags behind G.
  const auto output_side = run(on_output, steps(30000, 0.0, 600.0), 0.0);
  EXPECT_NEAR(saturated.back(), output_side.back(), 1e-4);  // 30 s: 16 slow time constants
  EXPECT_LT(saturated[1000], output_side[1000] - 1.0);
}

TEST(Effect, ASaturationIsOnTheDisplacementOrOnTheDriveNothingBetween) {
  EXPECT_NO_THROW(validate({EffectKind::saturation, {10.0, 20.0, 1.0}}, Ts, "e"));
  EXPECT_NO_THROW(validate({EffectKind::saturation, {10.0, 20.0}}, Ts, "e"));  // older files: the displacement
  try {
    validate({EffectKind::saturation, {10.0, 20.0, 0.5}}, Ts, "model.effect[0]");
    FAIL() << "on_drive = 0.5 accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "model.effect[0].on_drive");
  }
}

TEST(Effect, EveryFormChoiceIsZeroOrOneAndTheErrorNamesIt) {
  struct Case {
    EffectKind kind;
    size_t index;
    const char* name;
  };
  for (const auto& [kind, index, name] : {Case{EffectKind::saturation, 2, "on_drive"}, Case{EffectKind::slew_limit, 1, "digital"},
                                          Case{EffectKind::asymmetric_dynamics, 1, "slow_pole_only"},
                                          Case{EffectKind::bias_dependent_dynamics, 4, "slow_pole_only"}}) {
    ASSERT_EQ(form_flag_index(kind), index) << to_string(kind);
    // Only the slow-pole choice says G's slowest pole moves alone.
    EXPECT_EQ(slow_pole_only_index(kind), std::string(name) == "slow_pole_only" ? std::optional<size_t>(index) : std::nullopt)
        << to_string(kind);
    Effect e{kind, {}};
    const auto specs = parameter_specs(kind, DataScale::unbounded(Ts));
    for (size_t i = 0; i < specs.size(); ++i)  // a valid value for each: its default where it has one
      e.p[i] = std::isfinite(specs[i].default_value) ? specs[i].default_value : specs[i].lower;
    for (double value : {0.0, 1.0}) {
      e.p[index] = value;
      EXPECT_NO_THROW(validate(e, Ts, "e")) << to_string(kind) << " " << value;
    }
    e.p[index] = 0.5;
    try {
      validate(e, Ts, "e");
      ADD_FAILURE() << to_string(kind) << "." << name << " = 0.5 accepted";
    } catch (const ConfigError& error) {
      EXPECT_EQ(error.key(), std::string("e.") + name);
      EXPECT_NE(std::string(error.what()).find("got 0.5"), std::string::npos) << error.what();
    }
  }
  EXPECT_FALSE(form_flag_index(EffectKind::hysteresis));
  EXPECT_FALSE(form_flag_index(EffectKind::creep));
}

TEST(Effect, ScalingTheDisplacementScalesOnlyTheParametersInMicrometres) {
  const Effect saturation{EffectKind::saturation, {40.0, 8.0, 1.0, -3.0}};
  EXPECT_EQ(with_displacement_scaled(saturation, 0.5).p, (std::array<double, kMaxEffectParams>{20.0, 4.0, 1.0, -1.5}));
  const Effect drift{EffectKind::drift, {2.0, 0.1, 5.0, 30.0, 0.0}};
  const auto scaled_drift = with_displacement_scaled(drift, 2.0).p;
  EXPECT_EQ(scaled_drift[0], 4.0);   // offset_um
  EXPECT_EQ(scaled_drift[1], 0.2);   // rate_um_per_s
  EXPECT_EQ(scaled_drift[2], 5.0);   // onset in s
  const Effect bias{EffectKind::bias_dependent_dynamics, {0.3, 0.5, 120.0, 0.1, 1.0, 60.0}};
  EXPECT_EQ(with_displacement_scaled(bias, 0.8).p, (std::array<double, kMaxEffectParams>{0.3, 0.5, 96.0, 0.1, 1.0, 48.0}));
  // reference_um and centre_um; beta, tau, amplitude_beta and the form stay
  const Effect loop{EffectKind::hysteresis, {0.1, 20.0, 0.5}};
  EXPECT_EQ(with_displacement_scaled(loop, 0.8).p, loop.p);  // volts and shares
}

// The unit in a parameter's name (what files and JSON say) and the power of micrometres its spec
// declares (what with_displacement_scaled uses) must agree: "um" before any "per" is a power of 1, after
// it -1, no "um" 0.
TEST(Effect, EveryParametersDisplacementPowerMatchesTheUnitInItsName) {
  int in_micrometres = 0;
  for (EffectKind kind : kCandidateEffects)
    for (const auto& spec : parameter_specs(kind, DataScale::unbounded(1e-3))) {
      int expected = 0, sign = 1;
      std::istringstream tokens(spec.name);
      for (std::string token; std::getline(tokens, token, '_');) {
        if (token == "per") sign = -1;
        if (token == "um") expected += sign;
      }
      EXPECT_EQ(spec.displacement_power, expected) << to_string(kind) << "." << spec.name;
      in_micrometres += spec.displacement_power != 0;
    }
  EXPECT_EQ(in_micrometres, 8);  // saturation 3 (bipolar: with its centre), drift 3, bias-dependent dynamics 2
}

TEST(DataScale, TheValueNearestZeroIsTheRangesNearEndOrZeroWhenItCrossesZero) {
  EXPECT_EQ(abs_nearest_zero(324.0, 456.0), 324.0);
  EXPECT_EQ(abs_nearest_zero(-456.0, -324.0), 324.0);
  EXPECT_EQ(abs_nearest_zero(-150.0, 150.0), 0.0);
  EXPECT_EQ(abs_nearest_zero(0.0, 1000.0), 0.0);
  const DataScale scale{.u_min_V = 323.0, .u_max_V = 456.0, .y_min_um = -125.0, .y_max_um = -74.0};
  EXPECT_EQ(scale.u_abs_nearest_V(), 323.0);
  EXPECT_EQ(scale.y_abs_nearest_um(), 74.0);
}

TEST(AugmentedPlant, WholeSampleDelayShiftsTheOutput) {
  const auto u = voltage(3000);
  const auto y0 = run({}, u, u[0]);
  const auto y = run({EffectKind::delay, {3 * Ts}}, u, u[0]);
  for (size_t k = 10; k < u.size(); ++k) ASSERT_NEAR(y[k], y0[k - 3], 1e-6) << k;
}

TEST(AugmentedPlant, ADelayLongerThanTheFittedRangeRunsAtTheLoopRate) {
  // 0.664 s at 1 kHz: a delay the diagnosis fitted on a 100 Hz recording (66 of its samples), 664 of
  // the sim's; the line is sized at construction, so it is neither refused nor wrapped.
  const auto u = voltage(4000);
  const auto y0 = run({}, u, u[0]);
  const auto y = run({EffectKind::delay, {0.664}}, u, u[0]);
  for (size_t k = 0; k < 665; ++k) ASSERT_NEAR(y[k], y0[0], 1e-9) << k;  // still at rest
  for (size_t k = 700; k < u.size(); ++k) ASSERT_NEAR(y[k], y0[k - 664], 1e-6) << k;
  const auto half = run({EffectKind::delay, {0.6645}}, u, u[0]);  // half a sample more: the mean of two
  for (size_t k = 700; k < u.size(); ++k) ASSERT_NEAR(half[k], 0.5 * (y0[k - 664] + y0[k - 665]), 0.05) << k;
}

TEST(AugmentedPlant, AFractionalDelayIsExactForAHeldCommand) {
  // The command held over each sample reaches the gel (1 + d) samples later, so it switches d into a
  // sample period. Reference: the same f and G stepped exactly on a grid ten times finer, where the
  // switch falls on a grid point (d = 0.4, 0.7). (Before, the command was interpolated linearly between
  // two samples ahead of f and G: a first-order approximation.)
  const HammersteinModel m = paper_model(3);
  const auto u = voltage(3000);
  const int sub = 10;
  const StateSpace fine = discretize_zoh(realize(m.G, "G"), Ts / sub);
  for (double d : {0.4, 0.7}) {
    AugmentedPlant plant(m, 1.0 + d, Ts, std::span<const Effect>{});
    plant.reset_steady_state(u[0]);
    Eigen::VectorXd x = (Eigen::MatrixXd::Identity(fine.A.rows(), fine.A.cols()) - fine.A).lu().solve(fine.B * m.f(u[0]));
    const auto held = [&](long j) {  // the command the gel sees over fine step j (time j Ts / sub)
      const long k = static_cast<long>(std::floor((static_cast<double>(j) / sub - 1.0 - d) + 1e-9));
      return u[static_cast<size_t>(std::clamp(k, 0L, static_cast<long>(u.size()) - 1))];
    };
    double worst = 0.0;
    for (size_t k = 0; k < u.size(); ++k) {
      worst = std::max(worst, std::abs(plant.output() - (fine.C.dot(x) + fine.D * m.f(held(static_cast<long>(k) * sub)))));
      plant.apply(u[k]);
      for (int j = 0; j < sub; ++j) x = fine.A * x + fine.B * m.f(held(static_cast<long>(k) * sub + j));
    }
    EXPECT_LT(worst, 1e-9) << "d " << d;
  }
}

TEST(AugmentedPlant, AsymmetricDynamicsSlowsTheRelaxation) {
  const auto up = steps(20000, 100.0, 400.0), down = steps(20000, 400.0, 100.0);
  const Effect e{EffectKind::asymmetric_dynamics, {1.0}};
  // Rising: nominal. Falling: twice as slow (time scale 1 + kappa).
  const auto y_up = run(e, up, 100.0), y0_up = run({}, up, 100.0);
  EXPECT_NEAR(y_up[3000], y0_up[3000], 1e-9);
  const auto y_dn = run(e, down, 400.0), y0_dn = run({}, down, 400.0);
  EXPECT_GT(y_dn[1000], y0_dn[1000] + 1.0);
  EXPECT_NEAR(y_dn[2000], y0_dn[1000], 0.05 * (y0_dn[0] - y0_dn[1000]));
}

TEST(AugmentedPlant, AsymmetricDynamicsWithTheNominalOnTheRelaxationSlowsTheRise) {
  // rise_share 1: the same ratio of speeds (relaxing 1 + kappa = 0.5 times rising's time scale), with the
  // nominal the relaxing direction's: rising runs twice as slow, relaxing at the nominal.
  const auto up = steps(20000, 100.0, 400.0), down = steps(20000, 400.0, 100.0);
  const Effect e{EffectKind::asymmetric_dynamics, {-0.5, 0.0, 1.0}};
  const auto y_dn = run(e, down, 400.0), y0_dn = run({}, down, 400.0);
  EXPECT_NEAR(y_dn[3000], y0_dn[3000], 1e-9);
  const auto y_up = run(e, up, 100.0), y0_up = run({}, up, 100.0);
  EXPECT_LT(y_up[1000], y0_up[1000] - 1.0);
  EXPECT_NEAR(y_up[2000], y0_up[1000], 0.05 * (y0_up[1000] - y0_up[0]));
  // Halfway (rise_share 0.5): each direction sqrt(2) off the nominal, the rise slower, the relaxation faster.
  const Effect half{EffectKind::asymmetric_dynamics, {-0.5, 0.0, 0.5}};
  EXPECT_LT(run(half, up, 100.0)[1000], y0_up[1000] - 0.5);
  EXPECT_LT(run(half, down, 400.0)[1000], y0_dn[1000] - 0.5);
}

TEST(AugmentedPlant, SlewLimitRampsTheVoltage) {
  const Effect e{EffectKind::slew_limit, {1000.0}};
  const auto y = run(e, steps(3000, 200.0, 300.5), 200.0);
  // The same as the nominal model driven by the sample means of a 1 V/sample
  // ramp: 200.5, 201.5, ..., 299.5, then 300.375 (0.5 V reached in half a sample).
  std::vector<double> ramp(3000, 300.5);
  ramp[0] = 200.0;
  for (size_t k = 1; k <= 100; ++k) ramp[k] = 199.5 + static_cast<double>(k);
  ramp[101] = 300.5 - 0.5 * 0.5 * 0.5;
  const auto y_ramp = run({}, ramp, 200.0);
  for (size_t k = 0; k < y.size(); ++k) ASSERT_NEAR(y[k], y_ramp[k], 1e-9) << k;
}

TEST(AugmentedPlant, DigitalSlewLimitHoldsTheLimitedStep) {
  const Effect e{EffectKind::slew_limit, {1000.0, 1.0}};
  const auto y = run(e, steps(3000, 200.0, 300.5), 200.0);
  // The same as the nominal model driven by a held 1 V/sample staircase: 201, 202, ..., 300, then 300.5.
  std::vector<double> stairs(3000, 300.5);
  stairs[0] = 200.0;
  for (size_t k = 1; k <= 100; ++k) stairs[k] = 200.0 + static_cast<double>(k);
  const auto y_stairs = run({}, stairs, 200.0);
  for (size_t k = 0; k < y.size(); ++k) ASSERT_NEAR(y[k], y_stairs[k], 1e-9) << k;
}

TEST(AugmentedPlant, ResonanceKeepsTheGainAndRingsAtItsFrequency) {
  const Effect e{EffectKind::resonance, {5.0, 0.05}};
  const auto u = steps(20000, 100.0, 300.0);
  const auto y = run(e, u, 100.0), y0 = run({}, u, 100.0);
  EXPECT_NEAR(y.back(), y0.back(), 1e-6);
  double diff_max = 0.0;
  for (size_t k = 0; k < y.size(); ++k) diff_max = std::max(diff_max, std::abs(y[k] - y0[k]));
  EXPECT_GT(diff_max, 0.5);
}

TEST(AugmentedPlant, DriftIsAnInputIndependentRampAfterItsOnset) {
  const Effect e{EffectKind::drift, {0.2, 0.05, 1.0}};
  const auto u = voltage(4000);
  const auto y = run(e, u, u[0]), y0 = run({}, u, u[0]);
  for (size_t k = 0; k < u.size(); ++k) {
    const double t = static_cast<double>(k) * Ts;
    ASSERT_NEAR(y[k] - y0[k], 0.2 + 0.05 * std::max(t - 1.0, 0.0), 1e-9) << k;
  }
}

TEST(AugmentedPlant, ASettlingDriftApproachesRateTimesItsSettlingTime) {
  // Thermal settling: offset, then from the onset rate * tau (1 - exp(-(t - onset) / tau)).
  const Effect e{EffectKind::drift, {0.2, 0.05, 1.0, 0.5}};
  const auto u = voltage(4000);
  const auto y = run(e, u, u[0]), y0 = run({}, u, u[0]);
  for (size_t k = 0; k < u.size(); ++k) {
    const double after = std::max(static_cast<double>(k) * Ts - 1.0, 0.0);
    ASSERT_NEAR(y[k] - y0[k], 0.2 + 0.05 * 0.5 * (1.0 - std::exp(-after / 0.5)), 1e-9) << k;
  }
  EXPECT_NEAR(y.back() - y0.back(), 0.2 + 0.025, 1e-4);  // 6 settling times after the onset: settled
}

TEST(AugmentedPlant, BiasDependentDynamicsAreSlowerAtHigherDisplacement) {
  const Effect e{EffectKind::bias_dependent_dynamics, {1.0}};
  const auto u = steps(60000, 0.0, 500.0);
  const auto y = run(e, u, 0.0), y0 = run({}, u, 0.0);
  EXPECT_NEAR(y.back(), y0.back(), 1e-3);  // same static gain (after ~15 slowed time constants)
  EXPECT_LT(y[500], y0[500] - 1.0);        // slower on the way up
}

TEST(AugmentedPlant, AmplitudeDependentDynamicsSlowALargeSwingAndLeaveAHoldAlone) {
  // amplitude_beta only: the time scale follows the low-passed swing |y - y_op|, not the level.
  const double y_ref = 50.0;
  const Effect e{EffectKind::bias_dependent_dynamics, {0.0, 1.0, y_ref, 2.0}};
  const auto sine = [](double amplitude_V) {
    std::vector<double> u(20000);
    for (size_t k = 0; k < u.size(); ++k) u[k] = 300.0 + amplitude_V * std::sin(2.0 * std::numbers::pi * static_cast<double>(k) * Ts);
    return u;
  };
  const auto lag_share = [&](double amplitude_V) {  // |y - y0| over the nominal's swing, last 5 s
    const auto u = sine(amplitude_V);
    const auto y = run(e, u, u[0]), y0 = run({}, u, u[0]);
    double d = 0.0, s = 0.0;
    for (size_t k = 15000; k < y.size(); ++k) d += std::abs(y[k] - y0[k]), s += std::abs(y0[k] - y0[15000]);
    return d / s;
  };
  EXPECT_GT(lag_share(200.0), 3.0 * lag_share(20.0));  // slowed much more by the large swing
  const std::vector<double> hold(5000, 400.0);
  const auto y = run(e, hold, 400.0), y0 = run({}, hold, 400.0);
  EXPECT_NEAR(y.back(), y0.back(), 1e-9);  // at rest nothing swings: the nominal plant exactly
}

TEST(AugmentedPlant, BiasDependentDynamicsOnTheSlowPoleAloneMoveItAndKeepItsGain) {
  // slow_pole_only: in G's modal form r1/(s + p1) + r2/(s + p2), p1 the slow pole, the slow mode alone runs
  // N = 1 + beta y / y_ref times slower (its DC gain r1 / p1 kept): slow_pole_reference.
  const auto model = paper_model(3);
  const double beta = 1.5, y_ref = model.G.dc_gain() * model.f(500.0);
  const Effect e{EffectKind::bias_dependent_dynamics, {beta, 0.0, y_ref, 0.0, 1.0}};
  const auto u = up_and_down();
  const auto y = run(e, u, 0.0), y_all = run({EffectKind::bias_dependent_dynamics, {beta, 0.0, y_ref}}, u, 0.0);
  const double largest_error = gap_to(y, slow_pole_reference(model, u, beta, y_ref, 0.0)).largest;
  const double largest_gap_to_all = gap_to(y, y_all).largest;
  const double span_um = model.G.dc_gain() * model.f(600.0);
  std::printf("slow pole alone: largest error %.4f um against the modal reference, %.3f um from all poles scaled "
              "(span %.1f um)\n", largest_error, largest_gap_to_all, span_um);
  EXPECT_LT(largest_error, 5e-4 * span_um);  // the 41-point grid's interpolation
  EXPECT_GT(largest_gap_to_all, 0.02 * span_um);  // and it is not the all-poles form
}

TEST(AugmentedPlant, BiasDependentDynamicsAboutACentreRunTheNominalThereAndMoveWithTheDistanceFromIt) {
  // centre_um c: N = 1 + beta (y - c) / y_ref, so a nominal identified about an operating point holds there.
  // Reference: slow_pole_reference, on the slow pole alone.
  const auto model = paper_model(3);
  const double beta = -1.2, y_ref = model.G.dc_gain() * model.f(600.0), centre = model.G.dc_gain() * model.f(400.0);
  const Effect e{EffectKind::bias_dependent_dynamics, {beta, 0.0, y_ref, 0.0, 1.0, centre}};
  const auto u = up_and_down();
  EXPECT_LT(gap_to(run(e, u, 0.0), slow_pole_reference(model, u, beta, y_ref, centre)).largest, 5e-4 * y_ref);
  // A small step about the centre: the nominal's response (N within 1 +- 0.02); the same effect centred at zero
  // runs it there with N = 1 - 1.2 x 0.37, near twice as fast.
  std::vector<double> small(4000, 405.0);
  small[0] = 400.0;
  const auto about = run(e, small, 400.0), nominal = run({}, small, 400.0);
  Effect at_zero = e;
  at_zero.p[5] = 0.0;
  const auto from_zero = run(at_zero, small, 400.0);
  const auto gap = [&](const std::vector<double>& v) { return gap_to(v, nominal).largest; };
  const double step_um = nominal.back() - nominal.front();
  std::printf("step %.3f um: %.4f um from the nominal about the centre, %.4f um centred at zero\n", step_um, gap(about),
              gap(from_zero));
  EXPECT_LT(gap(about), 0.02 * step_um);
  EXPECT_GT(gap(from_zero), 0.05 * step_um);
  EXPECT_LT(gap(about), 0.1 * gap(from_zero));
}

TEST(AugmentedPlant, BiasDependentDynamicsOnTheSlowPoleAloneBesideCreepMoveGsSlowPoleAloneNotTheCreeps) {
  // The reference with a creep branch c G(0) / (tau s + 1) in parallel, stepped exactly with its own pole: the
  // block beside creep is realised in parts, so only G's slow mode runs N times slower.
  const auto model = paper_model(3);
  const double beta = 1.5, y_ref = model.G.dc_gain() * model.f(500.0), c = 0.2, tau_s = 5.0;
  const std::vector<Effect> e{{EffectKind::bias_dependent_dynamics, {beta, 0.0, y_ref, 0.0, 1.0}},
                              {EffectKind::creep, {c, tau_s}}};
  const auto u = up_and_down();
  AugmentedPlant plant(model, 1, Ts, e);
  const double largest_error = gap_to(plant.simulate(u, 0.0), slow_pole_reference(model, u, beta, y_ref, 0.0, c, tau_s)).largest;
  const double span_um = model.G.dc_gain() * (1.0 + c) * model.f(600.0);
  EXPECT_LT(largest_error, 5e-4 * span_um);  // the 41-point grid's interpolation, as above
}

TEST(AugmentedPlant, TheSlowPoleAloneBesideAModeOrCreepIsTheFoldedBlockWhenItDoesNotMove) {
  // beta = 0: G's slow pole does not move, so the block realised in parts (G, creep, mode as separate states)
  // must give the folded block's response: the same transfer function in another realisation.
  const auto model = paper_model(3);
  const Effect still{EffectKind::bias_dependent_dynamics, {0.0, 0.0, 10.0, 0.0, 1.0}};
  const auto u = steps(6000, 0.0, 500.0);
  for (const Effect& other : {Effect{EffectKind::resonance, {12.0, 0.05, 0.3, 0.2}}, Effect{EffectKind::creep, {0.3, 2.0, 1.0}}}) {
    const std::vector<Effect> both{still, other};
    AugmentedPlant in_parts(model, 1, Ts, both), folded(model, 1, Ts, other);
    const auto gap = gap_to(in_parts.simulate(u, 0.0), folded.simulate(u, 0.0));
    EXPECT_LT(gap.largest, 1e-9 * gap.span) << to_string(other.kind);
    EXPECT_GT(gap.span, 10.0);
  }
}

/// A 10 kHz piezo (G's poles at 125 and 290 Hz) with a 313 Hz mode of damping 0.012 beside asymmetric dynamics
/// on G's slow pole that do not move it: realised in parts, the block was discretised unstable (a badly scaled
/// matrix exponential) before 7fdcb00 and ran to infinity within 30 samples (seed 117's case011,
/// tests/data/nan_pair_start).
struct LightModeOnAPiezo {
  HammersteinModel piezo{OddPolynomial({0.0709, 4.54e-7}), TransferFunction({1.284e6}, {1.0, 2722.6, 1.6189e6})};
  double Ts_s = 1e-4;
  Effect still{EffectKind::asymmetric_dynamics, {0.0, 1.0}}, mode{EffectKind::resonance, {312.602, 0.0124488, 0.0, 0.0}};
  std::vector<Effect> both{still, mode};
};

TEST(AugmentedPlant, TheSlowPoleAloneBesideALightModeOnAFastGIsTheFoldedBlockWhenItDoesNotMove) {
  // The same on LightModeOnAPiezo.
  const LightModeOnAPiezo c;
  const auto u = steps(3000, -57.0, 40.0);
  AugmentedPlant in_parts(c.piezo, 0, c.Ts_s, c.both), folded(c.piezo, 0, c.Ts_s, c.mode);
  const auto y = in_parts.simulate(u, u[0]);
  ASSERT_TRUE(std::all_of(y.begin(), y.end(), [](double v) { return std::isfinite(v); }));
  const auto gap = gap_to(y, folded.simulate(u, u[0]));
  EXPECT_LT(gap.largest, 1e-7 * gap.span);
  EXPECT_GT(gap.span, 2.0);
}

TEST(AugmentedPlant, ItsLargestDiscretePoleIsTheSlowestContinuousPoleMapped) {
  // What the sim backend checks before it runs an augmented model: every grid entry's poles are exp(lambda Ts).
  // LightModeOnAPiezo, realised in parts: 8.2 here before 7fdcb00; now G's slow pole mapped.
  const LightModeOnAPiezo c;
  double slowest = -INFINITY;
  for (const auto& pole : c.piezo.G.poles()) slowest = std::max(slowest, pole.real());
  const double mode_modulus = std::exp(-c.mode.p[1] * 2.0 * std::numbers::pi * c.mode.p[0] * c.Ts_s);
  const double expected = std::max(std::exp(slowest * c.Ts_s), mode_modulus);
  EXPECT_NEAR(AugmentedPlant(c.piezo, 0, c.Ts_s, c.both).largest_discrete_pole_modulus(), expected, 1e-9);
  EXPECT_NEAR(AugmentedPlant(c.piezo, 0, c.Ts_s, c.mode).largest_discrete_pole_modulus(), expected, 1e-9);
  // Asymmetric dynamics with kappa 1 add the entry that relaxes twice as slowly: its slow pole at half the rate.
  const Effect slower{EffectKind::asymmetric_dynamics, {1.0, 1.0}};
  EXPECT_NEAR(AugmentedPlant(c.piezo, 0, c.Ts_s, slower).largest_discrete_pole_modulus(), std::exp(slowest * c.Ts_s / 2.0),
              1e-9);
}

TEST(AugmentedPlant, AsymmetricDynamicsOnTheSlowPoleAloneSlowOnlyItsRelaxation) {
  // slow_pole_only: in G's modal form r1/(s + p1) + r2/(s + p2), p1 the slow pole, the slow mode alone runs
  // 1 + kappa times slower while the displacement relaxes (G(0) f below it), its DC gain kept; the fast mode
  // runs as in G both ways. Reference: that form stepped exactly over each sample (ZOH), the plant's 1-sample
  // I/O delay.
  const auto model = paper_model(3);
  const double kappa = 1.5;
  const Effect e{EffectKind::asymmetric_dynamics, {kappa, 1.0}};
  const auto [p1, p2, r1, r2] = paper_modes(model);
  const double dc_gain = model.G.dc_gain();
  const auto u = up_and_down();
  const auto y = run(e, u, 0.0), y_all = run({EffectKind::asymmetric_dynamics, {kappa}}, u, 0.0);
  double x1 = 0.0, x2 = 0.0, largest_error = 0.0, largest_gap_to_all = 0.0;
  for (size_t k = 1; k < u.size(); ++k) {
    const double y_before = r1 * x1 + r2 * x2, w = model.f(k >= 2 ? u[k - 2] : 0.0);
    const double N = dc_gain * w < y_before ? 1.0 + kappa : 1.0;
    const double a1 = std::exp(-p1 * Ts / N), a2 = std::exp(-p2 * Ts);
    x1 = a1 * x1 + (1.0 - a1) * w / p1;
    x2 = a2 * x2 + (1.0 - a2) * w / p2;
    largest_error = std::max(largest_error, std::abs(y[k] - (r1 * x1 + r2 * x2)));
    largest_gap_to_all = std::max(largest_gap_to_all, std::abs(y[k] - y_all[k]));
  }
  const double span_um = dc_gain * model.f(600.0);
  std::printf("asymmetric, slow pole alone: largest error %.2e um against the modal reference, %.3f um from all "
              "poles slowed (span %.1f um)\n", largest_error, largest_gap_to_all, span_um);
  EXPECT_LT(largest_error, 1e-6 * span_um);  // two exact discretisations, no interpolation
  EXPECT_GT(largest_gap_to_all, 0.01 * span_um);  // and it is not the all-poles form
}

TEST(AugmentedPlant, AsymmetricAndBiasDependentDynamicsMultiplyTheirSlowdowns) {
  // Both at once, each on G's slow pole alone or on all of G: the slow mode runs N_d N_b times slower, N_d =
  // 1 + kappa while relaxing (else 1), N_b = 1 + beta y / y_ref; the fast mode by the factors of the effects
  // that move all of G. Reference: G's modal form stepped exactly over each sample, as above.
  const auto model = paper_model(3);
  const double kappa = 1.5, beta = 1.5, y_ref = model.G.dc_gain() * model.f(500.0), dc_gain = model.G.dc_gain();
  const auto [p1, p2, r1, r2] = paper_modes(model);
  const auto u = up_and_down();
  const double span_um = dc_gain * model.f(600.0);
  for (const double direction_slow : {0.0, 1.0}) {
    for (const double bias_slow : {0.0, 1.0}) {
      const std::vector<Effect> both{{EffectKind::asymmetric_dynamics, {kappa, direction_slow}},
                                     {EffectKind::bias_dependent_dynamics, {beta, 0.0, y_ref, 0.0, bias_slow}}};
      AugmentedPlant plant(model, 1, Ts, both);
      const auto y = plant.simulate(u, 0.0);
      double x1 = 0.0, x2 = 0.0, largest_error = 0.0;
      for (size_t k = 1; k < u.size(); ++k) {
        const double y_before = r1 * x1 + r2 * x2, w = model.f(k >= 2 ? u[k - 2] : 0.0);
        const double n_d = dc_gain * w < y_before ? 1.0 + kappa : 1.0;
        const double n_b = std::clamp(1.0 + beta * y_before / y_ref, 0.25, 4.0);
        const double fast = (direction_slow != 0.0 ? 1.0 : n_d) * (bias_slow != 0.0 ? 1.0 : n_b);
        const double a1 = std::exp(-p1 * Ts / (n_d * n_b)), a2 = std::exp(-p2 * Ts / fast);
        x1 = a1 * x1 + (1.0 - a1) * w / p1;
        x2 = a2 * x2 + (1.0 - a2) * w / p2;
        largest_error = std::max(largest_error, std::abs(y[k] - (r1 * x1 + r2 * x2)));
      }
      std::printf("asymmetric (slow pole only %g) and bias-dependent (%g): largest error %.2e um (span %.1f um)\n",
                  direction_slow, bias_slow, largest_error, span_um);
      EXPECT_LT(largest_error, 5e-4 * span_um) << direction_slow << " " << bias_slow;  // the bias grid's interpolation
    }
  }
  // Neither slows anything at beta 0 while rising: the nominal then (the relaxation alone slowed).
  const std::vector<Effect> flat{{EffectKind::asymmetric_dynamics, {kappa}}, {EffectKind::bias_dependent_dynamics, {0.0}}};
  AugmentedPlant plant(model, 1, Ts, flat);
  const auto y = plant.simulate(steps(3000, 100.0, 400.0), 100.0), y0 = run({}, steps(3000, 100.0, 400.0), 100.0);
  EXPECT_LT(gap_to(y, y0).largest, 1e-9 * span_um);
}

TEST(AugmentedPlant, AsymmetricDynamicsBesideCreepRiseAllTheWayToTheBlocksGain) {
  // Creep adds 20% slow gain: the block settles at 1.2 G(0) f. A monotone rise is rising until it arrives,
  // so it is creep alone's rise; compared with G(0) f, it turned "relaxing" at 1/1.2 of the way.
  const auto u = steps(20000, 100.0, 400.0);
  const Effect creep{EffectKind::creep, {0.2, 3.0}};
  const auto alone = run(creep, u, 100.0);
  ASSERT_TRUE(std::is_sorted(alone.begin(), alone.end())) << "the reference rise is not monotone";
  for (double slow_pole_only : {0.0, 1.0}) {
    const std::vector<Effect> both{{EffectKind::asymmetric_dynamics, {1.0, slow_pole_only}}, creep};
    AugmentedPlant plant(paper_model(3), 1, Ts, both);
    const auto y = plant.simulate(u, 100.0);
    double worst = 0.0;
    for (size_t k = 0; k < y.size(); ++k) worst = std::max(worst, std::abs(y[k] - alone[k]));
    EXPECT_LT(worst, 1e-9 * (alone.back() - alone.front())) << "slow_pole_only " << slow_pole_only;
  }
}

TEST(Effect, OnlyASlowRealPoleMovesAlone) {
  try {
    validate({EffectKind::bias_dependent_dynamics, {0.2, 0.0, 10.0, 0.0, 0.5}}, Ts, "model.effect[0]");
    FAIL() << "slow_pole_only = 0.5 accepted";
  } catch (const ConfigError& err) {
    EXPECT_EQ(err.key(), "model.effect[0].slow_pole_only");
  }
  const HammersteinModel first_order{paper_model(3).f, TransferFunction({5.0}, {0.1, 1.0})};
  try {
    AugmentedPlant p(first_order, 1, Ts, {EffectKind::bias_dependent_dynamics, {0.2, 0.0, 10.0, 0.0, 1.0}});
    FAIL() << "a first-order G accepted";
  } catch (const ConfigError& err) {
    EXPECT_EQ(err.key(), "effect.bias_dependent_dynamics.slow_pole_only");
    EXPECT_NE(std::string(err.what()).find("first order"), std::string::npos) << err.what();
  }
  // Beside creep the block runs G's states apart from the creep's: G's slow mode stays its own.
  const std::vector<Effect> with_creep{{EffectKind::bias_dependent_dynamics, {0.2, 0.0, 10.0, 0.0, 1.0}},
                                       {EffectKind::creep, {0.1, 3.0}}};
  EXPECT_NO_THROW(validate_mixture(with_creep, "model.effect"));
  // G's own slowest pole must still be real: a first-order G beside creep has none to move alone.
  const std::vector<Effect> first_order_with_creep{{EffectKind::bias_dependent_dynamics, {0.2, 0.0, 10.0, 0.0, 1.0}},
                                                   {EffectKind::creep, {0.1, 3.0}}};
  EXPECT_THROW(AugmentedPlant(first_order, 1, Ts, first_order_with_creep), ConfigError);
  const std::vector<Effect> with_loop{{EffectKind::bias_dependent_dynamics, {0.2, 0.0, 10.0, 0.0, 1.0}},
                                      {EffectKind::hysteresis, {0.1, 20.0}}};
  EXPECT_NO_THROW(validate_mixture(with_loop, "model.effect"));
}

TEST(Effect, AsymmetricDynamicsMoveTheSlowPoleAloneUnderTheSameRules) {
  try {
    validate({EffectKind::asymmetric_dynamics, {0.2, 0.5}}, Ts, "model.effect[0]");
    FAIL() << "slow_pole_only = 0.5 accepted";
  } catch (const ConfigError& err) {
    EXPECT_EQ(err.key(), "model.effect[0].slow_pole_only");
  }
  const HammersteinModel first_order{paper_model(3).f, TransferFunction({5.0}, {0.1, 1.0})};
  try {
    AugmentedPlant p(first_order, 1, Ts, {EffectKind::asymmetric_dynamics, {0.2, 1.0}});
    FAIL() << "a first-order G accepted";
  } catch (const ConfigError& err) {
    EXPECT_EQ(err.key(), "effect.asymmetric_dynamics.slow_pole_only");
  }
  // Beside a mode or creep the slow pole is G's own (the block realised in parts).
  const std::vector<Effect> with_mode{{EffectKind::asymmetric_dynamics, {0.2, 1.0}}, {EffectKind::resonance, {40.0, 0.1}}};
  EXPECT_NO_THROW(validate_mixture(with_mode, "model.effect"));
  const std::vector<Effect> all_poles{{EffectKind::asymmetric_dynamics, {0.2, 0.0}}, {EffectKind::resonance, {40.0, 0.1}}};
  EXPECT_NO_THROW(validate_mixture(all_poles, "model.effect"));
}

TEST(AugmentedPlant, RestVoltageInvertsTheSteadyState) {
  AugmentedPlant p(paper_model(3), 1, Ts, {EffectKind::creep, {0.01, 3.0}});
  p.reset_steady_state(321.0);
  const double y = p.output();
  EXPECT_NEAR(p.rest_voltage(y, 0.0, 800.0), 321.0, 1e-6);
}

TEST(Effect, ParametersOutOfBoundsAreRejectedWithTheirKey) {
  try {
    AugmentedPlant p(paper_model(3), 1, Ts, {EffectKind::dead_zone, {-3.0, 10.0}});
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "effect.dead_zone.threshold_V");
  }
}

TEST(Effect, ADelayIsBoundedByTheLinesLengthInLoopSamplesAndTheFitByItsOwn) {
  EXPECT_NO_THROW(AugmentedPlant(paper_model(3), 1, Ts, {EffectKind::delay, {2.0}}));
  try {
    AugmentedPlant p(paper_model(3), 1, Ts, {EffectKind::delay, {(kMaxDelaySamples + 1.0) * Ts}});
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "effect.delay.extra_delay_s");
  }
  // What diagnose fits: at most kFittedDelaySamples of the fastest recording.
  DataScale recorded;
  recorded.sample_time_s = 0.01;
  recorded.sample_time_min_s = 0.005;
  EXPECT_DOUBLE_EQ(parameter_specs(EffectKind::delay, recorded)[0].upper, kFittedDelaySamples * 0.005);
}

TEST(Effect, NamesRoundTrip) {
  for (auto k : kCandidateEffects) EXPECT_EQ(parse_effect_kind(to_string(k)), k);
  EXPECT_FALSE(parse_effect_kind("gravity"));
}

TEST(AugmentedPlant, AParallelModeIsTheShareRhoOfGZeroTimesTheMode) {
  // (1 - rho) G + rho G(0) M(s), M = wn^2 / (s^2 + 2 zeta wn s + wn^2), with no series part (d = 1).
  const auto G = paper_model(3).G;
  const double f_Hz = 6.0, zeta = 0.03, rho = 0.04, wn = 2.0 * std::numbers::pi * f_Hz;
  const Effect e{EffectKind::resonance, {f_Hz, zeta, 1.0, rho}};
  const auto L = linear_block(G, std::span<const Effect>(&e, 1));
  for (double w : {0.0, 0.3, 3.0, wn, 100.0}) {
    const std::complex<double> s(0.0, w);
    const auto expected = (1.0 - rho) * G(s) + rho * G.dc_gain() * wn * wn / (s * s + 2.0 * zeta * wn * s + wn * wn);
    EXPECT_NEAR(std::abs(L(s) - expected), 0.0, 1e-9 * std::abs(expected)) << "at " << w << " rad/s";
  }
}

TEST(AugmentedPlant, AParallelModeRingsAtItsShareOfTheWholeStepAndKeepsTheGain) {
  // Fed by the force, the mode sees the step's whole displacement G(0) dx, not G's filtered response:
  // its first overshoot alone is about rho times the step.
  const auto u = steps(20000, 100.0, 300.0);
  const auto y0 = run({}, u, 100.0), y = run({EffectKind::resonance, {6.0, 0.03, 1.0, 0.04}}, u, 100.0);
  double peak = 0.0;
  for (size_t k = 0; k < y.size(); ++k) peak = std::max(peak, std::abs(y[k] - y0[k]));
  const double step_um = y0.back() - y0.front();
  EXPECT_GT(peak, 0.04 * step_um);
  EXPECT_LT(peak, 0.04 * 2.0 * step_um);  // at most the mode's whole overshoot (1.91 at zeta 0.03)
  EXPECT_NEAR(y.back(), y0.back(), 1e-3);  // the same gain (G's slow pole is 5e-6 from settled at 20 s)
}

}  // namespace
}  // namespace pvcgel::control::diagnosis

namespace pvcgel::control::diagnosis {
namespace {

std::vector<Effect> parse_effects(const std::string& text) {
  const auto root = toml::parse(text);
  TableReader top(&root, "");
  auto sim = top.table("sim");
  auto truth = sim.table("truth");
  return read_effect_tables(truth, "effect", 1e-3);
}

std::string parse_error(const std::string& text) {
  try {
    (void)parse_effects(text);
  } catch (const ConfigError& e) {
    return e.key();
  }
  return "no error";
}

TEST(Effect, ADriftWithoutASettlingTimeIsTheRampOfOlderFiles) {
  const auto specs = parameter_specs(EffectKind::drift, DataScale{});
  ASSERT_EQ(specs.size(), 5u);
  EXPECT_EQ(specs[3].name, "settling_time_s");
  EXPECT_EQ(specs[3].default_value, 0.0);
  EXPECT_EQ(specs[kDriftWander].name, "wander_um_per_sqrt_s");
  EXPECT_EQ(specs[kDriftWander].default_value, 0.0);
  const auto drift = parse_effects("[[sim.truth.effect]]\nname = \"drift\"\noffset_um = 0.1\nrate_um_per_s = 0.2\nonset_s = 0\n");
  ASSERT_EQ(drift.size(), 1u);
  EXPECT_EQ(drift[0].p[3], 0.0);
  EXPECT_EQ(drift[0].p[kDriftWander], 0.0);  // an older file's drift does not wander
  EXPECT_EQ(parse_error("[[sim.truth.effect]]\nname = \"drift\"\noffset_um = 0\nrate_um_per_s = 0\nonset_s = 0\n"
                        "wander_um_per_sqrt_s = -0.1\n"),
            "sim.truth.effect[0].wander_um_per_sqrt_s");
  EXPECT_DOUBLE_EQ(drift_um(drift[0].p, 30.0), 0.1 + 0.2 * 30.0);
  // The fit reaches a ramp within its bounds: a settling time a thousand recordings long bends it by 0.05%.
  const std::array<double, kMaxEffectParams> long_settling{0.0, 1.0, 0.0, 1e3 * DataScale{}.duration_s};
  EXPECT_NEAR(drift_um(long_settling, DataScale{}.duration_s), DataScale{}.duration_s, 1e-3 * DataScale{}.duration_s);
}

TEST(Effect, ADriftOnsetStaysInTheFirstNineTenthsOfTheFitSegment) {
  DataScale d;
  d.duration_s = 14.0;
  d.fit_end_s = 9.8;  // a recording whose last fitted sample is at 9.8 s
  const auto specs = parameter_specs(EffectKind::drift, d);
  EXPECT_DOUBLE_EQ(specs[2].upper, 0.9 * 9.8);
  for (double start : specs[2].starts) EXPECT_LE(start, specs[2].upper);
  // Nothing held out (a file's parameters, checked against the union of all scales): the whole recording.
  EXPECT_DOUBLE_EQ(parameter_specs(EffectKind::drift, DataScale{}).at(2).upper, DataScale{}.duration_s);
}

TEST(Effect, ASaturationFitsACentreOnlyOnAStrokeOfBothSignsAndStartsItsKneesWithinTheStroke) {
  DataScale unipolar;
  unipolar.y_min_um = 74.0;  // a sensor zeroed away from the stroke
  unipolar.y_max_um = 125.0;
  const auto one_signed = parameter_specs(EffectKind::saturation, unipolar);
  ASSERT_EQ(one_signed.size(), 3u);  // no centre: 0, the default, and not counted in the penalised score
  for (double knee : one_signed[0].starts) EXPECT_TRUE(knee == 0.0 || (knee >= 74.0 && knee < 125.0)) << knee;
  DataScale bipolar = unipolar;
  bipolar.y_min_um = -9.0;
  bipolar.y_max_um = 7.0;
  const auto both_signs = parameter_specs(EffectKind::saturation, bipolar);
  ASSERT_EQ(both_signs.size(), 4u);
  EXPECT_EQ(both_signs[3].name, "centre_um");
  EXPECT_DOUBLE_EQ(both_signs[3].lower, -9.0);
  EXPECT_DOUBLE_EQ(both_signs[3].default_value, 0.0);  // older files: symmetric about zero
  // A stroke that barely crosses zero is one-signed (its far stop alone can act).
  bipolar.y_min_um = -0.5;
  EXPECT_EQ(parameter_specs(EffectKind::saturation, bipolar).size(), 3u);
  // A file's saturation (checked against every scale) may carry a centre.
  EXPECT_EQ(parameter_specs(EffectKind::saturation, DataScale::unbounded(1e-3)).size(), 4u);
}

TEST(EffectTables, AListDominantFirstAndTheOldSingleTable) {
  const auto two = parse_effects(
      "[[sim.truth.effect]]\nname = \"hysteresis\"\nalpha = 0.05\nthreshold_scale_V = 20.0\n"
      "[[sim.truth.effect]]\nname = \"creep\"\nfraction = 0.02\ntime_constant_s = 5.0\n");
  ASSERT_EQ(two.size(), 2u);
  EXPECT_EQ(two[0].kind, EffectKind::hysteresis);
  EXPECT_DOUBLE_EQ(two[0].p[2], 0.0);  // threshold_spread: optional, the earlier exponential thresholds
  EXPECT_EQ(two[1].kind, EffectKind::creep);
  EXPECT_DOUBLE_EQ(two[1].p[1], 5.0);
  EXPECT_DOUBLE_EQ(two[1].p[2], 0.0);  // spread_decades: optional, one branch
  const auto one = parse_effects("[sim.truth.effect]\nname = \"resonance\"\nfrequency_Hz = 40.0\ndamping_ratio = 0.1\n");
  ASSERT_EQ(one.size(), 1u);
  EXPECT_DOUBLE_EQ(one[0].p[2], 0.0);  // direct_fraction: optional, a full mode
  const auto bias = parse_effects("[sim.truth.effect]\nname = \"bias_dependent_dynamics\"\nbeta = 0.2\n"
                                  "operating_point_time_constant_s = 1\n");
  ASSERT_EQ(bias.size(), 1u);
  EXPECT_DOUBLE_EQ(bias[0].p[5], 0.0);  // centre_um: optional, G the nominal's at zero displacement as before
  const auto centred = parse_effects("[sim.truth.effect]\nname = \"bias_dependent_dynamics\"\nbeta = 0.2\n"
                                     "operating_point_time_constant_s = 1\ncentre_um = 45.5\n");
  ASSERT_EQ(centred.size(), 1u);
  EXPECT_DOUBLE_EQ(centred[0].p[5], 45.5);
  EXPECT_TRUE(parse_effects("[sim.truth]\n").empty());
}

TEST(EffectTables, HysteresisThresholdSpreadIsReadAndBounded) {
  const auto shaped = parse_effects("[[sim.truth.effect]]\nname = \"hysteresis\"\nalpha = 0.5\nthreshold_scale_V = 0.02\n"
                                    "threshold_spread = 1.5\n");
  ASSERT_EQ(shaped.size(), 1u);
  EXPECT_DOUBLE_EQ(shaped[0].p[2], 1.5);
  EXPECT_EQ(parse_error("[[sim.truth.effect]]\nname = \"hysteresis\"\nalpha = 0.5\nthreshold_scale_V = 20.0\n"
                        "threshold_spread = -1.0\n"),
            "sim.truth.effect[0].threshold_spread");  // -1 would put every play at R (equal thresholds)
}

TEST(AugmentedPlant, HysteresisThresholdsAtSpreadZeroAreTheEarlierForm) {
  // Files written before threshold_spread existed mean r_i = R kPlayQuantiles[i], exactly.
  const auto r = play_thresholds(20.0, 0.0);
  for (size_t i = 0; i < r.size(); ++i) EXPECT_EQ(r[i], 20.0 * kPlayQuantiles[i]);
  // Every spread keeps them ascending (the compensator's inverse needs that); a positive one widens their range.
  for (double spread : {-0.85, -0.3, 1.0, 3.0}) {
    const auto q = play_thresholds(20.0, spread);
    for (size_t i = 1; i < q.size(); ++i) EXPECT_LT(q[i - 1], q[i]) << "spread " << spread;
    EXPECT_EQ(q.back() / q.front() > r.back() / r.front(), spread > 0.0) << "spread " << spread;
  }
}

TEST(EffectTables, ErrorsNameTheElementAndKey) {
  EXPECT_EQ(parse_error("[[sim.truth.effect]]\nname = \"creep\"\nfraction = 0.02\ntime_constant_s = 5.0\n"
                        "[[sim.truth.effect]]\nname = \"gravity\"\n"),
            "sim.truth.effect[1].name");
  EXPECT_EQ(parse_error("[[sim.truth.effect]]\nname = \"creep\"\nfraction = 0.02\n"), "sim.truth.effect[0].time_constant_s");
  EXPECT_EQ(parse_error("[[sim.truth.effect]]\nname = \"creep\"\nfraction = 0.02\ntime_constant_s = 5.0\ncolour = 1\n"),
            "sim.truth.effect[0].colour");
  EXPECT_EQ(parse_error("[[sim.truth.effect]]\nname = \"drift\"\noffset_um = 0\nrate_um_per_s = 0\nonset_s = 0\n"
                        "[[sim.truth.effect]]\nname = \"drift\"\noffset_um = 0\nrate_um_per_s = 0\nonset_s = 0\n"),
            "sim.truth.effect");
  // Both time-scaling effects run together (AugmentedPlant.AsymmetricAndBiasDependentDynamicsMultiplyTheirSlowdowns).
  EXPECT_EQ(parse_error("[[sim.truth.effect]]\nname = \"asymmetric_dynamics\"\nrelaxation_slowdown = 0.2\n"
                        "[[sim.truth.effect]]\nname = \"bias_dependent_dynamics\"\nbeta = 0.2\noperating_point_time_constant_s = 1\n"),
            "no error");
}

TEST(AugmentedPlant, AMixtureIsBothEffects) {
  // Hysteresis (input side) and creep (a parallel branch) compose: the mixture differs from each alone.
  const auto u = voltage(20000);
  const Effect h{EffectKind::hysteresis, {0.05, 20.0}}, c{EffectKind::creep, {0.02, 2.0}};
  const std::vector<Effect> both{h, c};
  AugmentedPlant p(paper_model(3), 1, Ts, std::span<const Effect>(both));
  const auto y = p.simulate(u, u[0]), yh = run(h, u, u[0]), yc = run(c, u, u[0]), y0 = run({}, u, u[0]);
  double worst_sum = 0.0, diff_h = 0.0, diff_c = 0.0;
  for (size_t k = 0; k < u.size(); ++k) {
    // To first order the two deviations add.
    worst_sum = std::max(worst_sum, std::abs((y[k] - y0[k]) - (yh[k] - y0[k]) - (yc[k] - y0[k])));
    diff_h = std::max(diff_h, std::abs(y[k] - yh[k]));
    diff_c = std::max(diff_c, std::abs(y[k] - yc[k]));
  }
  EXPECT_GT(diff_h, 0.3);
  EXPECT_GT(diff_c, 0.3);
  EXPECT_LT(worst_sum, 0.1 * std::min(diff_h, diff_c));
}

TEST(AugmentedPlant, APartialModeKeepsMostOfTheDirectResponse) {
  const auto u = steps(20000, 100.0, 300.0);
  const auto full = run({EffectKind::resonance, {5.0, 0.05, 0.0}}, u, 100.0);
  const auto partial = run({EffectKind::resonance, {5.0, 0.05, 0.95}}, u, 100.0);
  const auto y0 = run({}, u, 100.0);
  double ring_full = 0.0, ring_partial = 0.0;
  for (size_t k = 0; k < u.size(); ++k)
    ring_full = std::max(ring_full, std::abs(full[k] - y0[k])), ring_partial = std::max(ring_partial, std::abs(partial[k] - y0[k]));
  EXPECT_NEAR(ring_partial / ring_full, 0.05, 0.01);  // 5% participation
}

}  // namespace
}  // namespace pvcgel::control::diagnosis
