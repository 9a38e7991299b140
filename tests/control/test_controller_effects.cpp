// The controller compensating the effects of [[model.effect]] in closed loop, on a
// rig whose truth is the model plus those effects (AugmentedPlant via the sim rig).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <string>
#include <vector>

#include "control/closed_loop.hpp"
#include "control/controller.hpp"

namespace pvcgel::control {
namespace {

struct Truth {
  const char* name;
  std::vector<Effect> effects;
};

// Hysteresis (up to ~25 V of lag after a reversal, about 20 um at the references' 100 um)
// and creep (20% at 2 s), and both: larger than the 5% rigs, whose effects the DOB
// and the learned correction of inverse_pid_dob_ff already reduce to the noise floor.
const Effect kHysteresis{EffectKind::hysteresis, {0.3, 100.0}};
const Effect kCreep{EffectKind::creep, {0.2, 2.0}};
const std::vector<Truth> kTruths{{"hysteresis", {kHysteresis}}, {"creep", {kCreep}}, {"both", {kHysteresis, kCreep}}};

ClosedLoopRun track(const std::vector<Effect>& truth, const std::vector<Effect>& model_effects, const std::string& ref,
                    bool keep_trace = false, ControllerMode mode = ControllerMode::inverse_pid_dob_ff) {
  SimRigConfig rc = SimRigConfig{}.exactly(paper_model(2));
  rc.noise_sigma_um = 0.05;
  rc.quantization_um = 0.01;
  rc.added_effects = truth;
  SimulatedRig rig(rc);
  ControllerConfig cfg;
  cfg.mode = mode;
  cfg.effects = model_effects;
  Controller ctl(paper_model(2), cfg);
  // Two periods of the slowest reference after 10 s of start-up.
  return run_closed_loop(rig, ctl, *paper_reference(ref), 30.0, 10.0, keep_trace);
}

TEST(ControllerEffects, CompensationRemovesTheEffectsExcessErrorOnEveryReference) {
  // The loop's own floor: the true error (without sensor noise) the controller leaves on the
  // rig without any effect, where it feeds back nothing but sensor noise.
  for (const auto& ref : kPaperReferenceNames) {
    const double floor_um = track({}, {}, ref).errors.mean_abs_true_um;
    for (const auto& truth : kTruths) {
      const auto with = track(truth.effects, truth.effects, ref).errors;
      const auto without = track(truth.effects, {}, ref).errors;
      const double excess_with = with.mean_abs_true_um - floor_um, excess_without = without.mean_abs_true_um - floor_um;
      std::printf("%-10s %-6s mean|r - y_true| without effects %.4f um, with %.4f um (ratio %.2f; loop floor %.4f "
                  "um); measured mean|e| %.4f -> %.4f um, sensor noise %.4f um\n",
                  truth.name, ref.c_str(), without.mean_abs_true_um, with.mean_abs_true_um,
                  with.mean_abs_true_um / without.mean_abs_true_um, floor_um, without.mean_abs_um, with.mean_abs_um,
                  with.noise_mean_abs_um);
      // The effect's excess over the floor is (almost) gone; where there was one, it is cut by 80% or more.
      EXPECT_LE(excess_with, 0.2 * std::max(excess_without, 0.0) + 5e-4) << truth.name << " " << ref;
      EXPECT_LT(with.mean_abs_um, 1.1 * with.noise_mean_abs_um) << truth.name << " " << ref;
    }
  }
  // And there is an excess to remove on the fastest reference (the effects are not below the noise).
  const auto both_1Hz = track(kTruths[2].effects, {}, "1Hz").errors.mean_abs_true_um;
  EXPECT_GT(both_1Hz, 2.0 * track({}, {}, "1Hz").errors.mean_abs_true_um);
}

TEST(ControllerEffects, ASaturationOnTheDriveIsUndoneBeforeFInverse) {
  // The drive softens from a static 100 um (the references reach 125 um): an amplifier or a force limit.
  const std::vector<Effect> drive{{EffectKind::saturation, {100.0, 60.0, 1.0}}};
  double largest_excess_um = 0.0;
  for (const auto& ref : kPaperReferenceNames) {
    const double floor_um = track({}, {}, ref).errors.mean_abs_true_um;
    const auto with = track(drive, drive, ref).errors;
    const auto without = track(drive, {}, ref).errors;
    const double excess_with = with.mean_abs_true_um - floor_um, excess_without = without.mean_abs_true_um - floor_um;
    std::printf("drive saturation %-6s mean|r - y_true| without the effect %.4f um, with %.4f um (loop floor %.4f um)\n",
                ref.c_str(), without.mean_abs_true_um, with.mean_abs_true_um, floor_um);
    EXPECT_LE(excess_with, 0.2 * std::max(excess_without, 0.0) + 5e-4) << ref;
    largest_excess_um = std::max(largest_excess_um, excess_without);
  }
  EXPECT_GT(largest_excess_um, 0.01);  // there was something to undo
}

TEST(ControllerEffects, ModePidIsTunedOnTheSlopeOfASaturatedDrive) {
  // Mode pid has no inverse: at its operating point (100 um, beyond a 70 um knee) the rig's static
  // gain du -> dy is G(0) d/du S(f(u)), lower than G(0) f'(u) by the saturation's slope there.
  const auto model = paper_model(2);
  const double dc = model.G.dc_gain();
  const std::array<double, kMaxEffectParams> q{70.0, 60.0, 1.0};
  const auto static_um = [&](double u_V) { return dc * saturated_drive(model.f(u_V), dc, q); };
  double lo = 0.0, hi = 1000.0;  // the voltage at which the saturated rig rests at 100 um
  for (int i = 0; i < 100; ++i) ((static_um(0.5 * (lo + hi)) < 100.0) ? lo : hi) = 0.5 * (lo + hi);
  const double u_op = 0.5 * (lo + hi), h = 1e-3;
  const double expected_gain = (static_um(u_op + h) - static_um(u_op - h)) / (2.0 * h) / dc;

  ControllerConfig cfg;
  cfg.effects = {{EffectKind::saturation, {q[0], q[1], q[2]}}};
  const Controller with(model, cfg);
  const Controller without(model, ControllerConfig{});
  const auto gain = [](const Controller& c) {
    return c.design_plant(ControllerMode::pid).b.sum() / c.design_plant(ControllerMode::inverse_pid).b.sum();
  };
  std::printf("mode pid plant gain d drive(f(u))/du %.6f /V at the operating point (expected %.6f; without the effect %.6f)\n",
              gain(with), expected_gain, gain(without));
  EXPECT_NEAR(gain(with), expected_gain, 1e-6 * expected_gain);
  EXPECT_LT(gain(with), 0.8 * gain(without));  // the slope there is about 0.65
  EXPECT_TRUE(with.margins(ControllerMode::pid).stable());
}

TEST(ControllerEffects, WrongEffectsDoNotDestabilise) {
  // The controller believes twice the truth's hysteresis and creep.
  const std::vector<Effect> wrong{{EffectKind::hysteresis, {0.6, 200.0}}, {EffectKind::creep, {0.4, 4.0}}};
  for (const auto& ref : kPaperReferenceNames) {
    const auto run = track({kHysteresis, kCreep}, wrong, ref, true);
    const auto& u = run.trace.u_V;
    const auto [lo, hi] = std::minmax_element(u.begin(), u.end());
    std::printf("wrong effects %-6s mean|e| %.4f um, max|e| %.3f um, u in [%.1f, %.1f] V\n", ref.c_str(),
                run.errors.mean_abs_um, run.errors.max_abs_um, *lo, *hi);
    EXPECT_LT(run.errors.max_abs_um, 5.0) << ref;
    EXPECT_LT(run.errors.mean_abs_um, 1.0) << ref;
    EXPECT_GE(*lo, 0.0);
    EXPECT_LE(*hi, 1000.0);
  }
}

}  // namespace
}  // namespace pvcgel::control
