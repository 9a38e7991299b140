// The controller compensating the effects of [[model.effect]] in closed loop, on a
// rig whose truth is the model plus those effects (AugmentedPlant via the sim rig).
#include <gtest/gtest.h>

#include <algorithm>
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

// Hysteresis at about 5% of the references' 50 um peak-to-peak, creep at 5% with a 10 s
// time constant, and both (the three rigs).
const Effect kHysteresis{EffectKind::hysteresis, {0.15, 50.0}};
const Effect kCreep{EffectKind::creep, {0.05, 10.0}};
const std::vector<Truth> kTruths{{"hysteresis", {kHysteresis}}, {"creep", {kCreep}}, {"both", {kHysteresis, kCreep}}};

ClosedLoopRun track(const std::vector<Effect>& truth, const std::vector<Effect>& model_effects, const std::string& ref,
                    bool keep_trace = false) {
  SimRigConfig rc = SimRigConfig{}.exactly(paper_model(2));
  rc.noise_sigma_um = 0.05;
  rc.quantization_um = 0.01;
  rc.added_effects = truth;
  SimulatedRig rig(rc);
  ControllerConfig cfg;
  cfg.mode = ControllerMode::inverse_pid_dob_ff;
  cfg.effects = model_effects;
  Controller ctl(paper_model(2), cfg);
  // Two periods of the slowest reference after 10 s of start-up.
  return run_closed_loop(rig, ctl, *paper_reference(ref), 30.0, 10.0, keep_trace);
}

TEST(ControllerEffects, CompensationCutsTheTrackingErrorOnEveryReference) {
  for (const auto& truth : kTruths) {
    for (const auto& ref : kPaperReferenceNames) {
      const auto with = track(truth.effects, truth.effects, ref).errors;
      const auto without = track(truth.effects, {}, ref).errors;
      std::printf("%-10s %-6s mean|r - y_true| without effects %.4f um, with %.4f um (ratio %.2f); measured mean|e| "
                  "%.4f -> %.4f um, noise floor %.4f um\n",
                  truth.name, ref.c_str(), without.mean_abs_true_um, with.mean_abs_true_um,
                  with.mean_abs_true_um / without.mean_abs_true_um, without.mean_abs_um, with.mean_abs_um,
                  with.noise_mean_abs_um);
      EXPECT_LT(with.mean_abs_true_um, 0.5 * without.mean_abs_true_um) << truth.name << " " << ref;
      EXPECT_LT(with.mean_abs_um, 1.1 * with.noise_mean_abs_um) << truth.name << " " << ref;
    }
  }
}

TEST(ControllerEffects, WrongEffectsDoNotDestabilise) {
  // The controller believes twice the truth's hysteresis and creep (and creep 5x slower).
  const std::vector<Effect> wrong{{EffectKind::hysteresis, {0.3, 100.0}}, {EffectKind::creep, {0.1, 50.0}}};
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
