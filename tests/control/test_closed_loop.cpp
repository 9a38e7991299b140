#include "control/closed_loop.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace pvcgel::control {
namespace {

TEST(ClosedLoop, ErrorsAreComputedFromTheTraceOverTheSettledWindow) {
  ControllerConfig cfg;
  cfg.mode = ControllerMode::inverse_pid;
  Controller ctl(paper_model(2), cfg);
  SimulatedRig rig(SimRigConfig{});
  const auto ref = *paper_reference("1Hz");
  const double duration = 3.0, settle = 1.0;
  const auto run = run_closed_loop(rig, ctl, ref, duration, settle, true);
  const auto& tr = run.trace;
  ASSERT_EQ(tr.t_s.size(), 3000u);
  for (auto* v : {&tr.r_um, &tr.y_um, &tr.y_true_um, &tr.u_V, &tr.d_hat}) ASSERT_EQ(v->size(), 3000u);

  double sum = 0.0, sum_sq = 0.0, max_abs = 0.0, sum_true = 0.0, sum_noise = 0.0;
  long n = 0;
  for (size_t k = 0; k < tr.t_s.size(); ++k) {
    EXPECT_NEAR(tr.t_s[k], static_cast<double>(k) * 1e-3, 1e-12);
    EXPECT_NEAR(tr.r_um[k], ref(tr.t_s[k]), 1e-12);
    if (tr.t_s[k] < settle) continue;
    const double e = tr.r_um[k] - tr.y_um[k];
    sum += std::abs(e);
    sum_sq += e * e;
    max_abs = std::max(max_abs, std::abs(e));
    sum_true += std::abs(tr.r_um[k] - tr.y_true_um[k]);
    sum_noise += std::abs(tr.y_um[k] - tr.y_true_um[k]);
    ++n;
  }
  ASSERT_EQ(n, 2000);
  // Same sums in the same order: equal to rounding.
  EXPECT_NEAR(run.errors.mean_abs_um, sum / 2000.0, 1e-12);
  EXPECT_NEAR(run.errors.rms_um, std::sqrt(sum_sq / 2000.0), 1e-12);
  EXPECT_EQ(run.errors.max_abs_um, max_abs);
  EXPECT_NEAR(run.errors.mean_abs_true_um, sum_true / 2000.0, 1e-12);
  EXPECT_NEAR(run.errors.noise_mean_abs_um, sum_noise / 2000.0, 1e-12);
  // The loop tracks: a 25 um sine with sub-micrometre error.
  EXPECT_LT(run.errors.mean_abs_um, 1.0);
}

TEST(ClosedLoop, NoTraceUnlessAsked) {
  Controller ctl(paper_model(2), ControllerConfig{});
  SimulatedRig rig(SimRigConfig{});
  const auto run = run_closed_loop(rig, ctl, *paper_reference("0.5Hz"), 0.5, 0.1, false);
  EXPECT_TRUE(run.trace.t_s.empty());
  EXPECT_GT(run.errors.mean_abs_um, 0.0);
}

TEST(ClosedLoop, SameSeedSameRun) {
  auto once = [] {
    Controller ctl(paper_model(2), ControllerConfig{});
    SimulatedRig rig(SimRigConfig{});
    return run_closed_loop(rig, ctl, *paper_reference("multi"), 1.0, 0.2, false).errors;
  };
  const auto a = once(), b = once();
  EXPECT_EQ(a.mean_abs_um, b.mean_abs_um);
  EXPECT_EQ(a.max_abs_um, b.max_abs_um);
}

}  // namespace
}  // namespace pvcgel::control
