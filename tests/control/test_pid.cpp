#include "control/pid.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "control/lti_filter.hpp"
#include "control/output_stage.hpp"

namespace pvcgel::control {
namespace {

constexpr double kTs = 1e-3;

// A saturating loop: PID -> clamp [0, 1] V -> plant 1/(s + 1) (ZOH), reference r(t).
// Returns the applied voltage per sample. With `back_calculation` false the PID is told
// the unclamped value was applied, which disables the anti-windup path.
struct SaturationRun {
  std::vector<double> applied, integral;
};
SaturationRun run_saturating_loop(const PidGains& g, bool back_calculation, double r_high_s, double total_s) {
  Pid pid(g, kTs);
  OutputStage stage(0.0, 1.0, 0.0, kTs);
  LtiFilter plant(discretize_zoh(realize(TransferFunction({1.0}, {1.0, 1.0})), kTs));
  SaturationRun run;
  double y = 0.0;
  const long n = std::lround(total_s / kTs);
  for (long k = 0; k < n; ++k) {
    const double r = static_cast<double>(k) * kTs < r_high_s ? 5.0 : 0.0;  // 5 is unreachable: the plant tops out at 1
    const double e = r - y;
    const double c = pid.output(e);
    const double u = stage.apply(c);
    pid.commit(e, c, back_calculation ? u : c);
    y = plant.step(u);
    run.applied.push_back(u);
    run.integral.push_back(pid.integral());
  }
  return run;
}

// Samples after the reversal until the applied output first leaves the upper limit.
long samples_to_leave_saturation(const SaturationRun& run, long reversal) {
  for (long k = reversal; k < static_cast<long>(run.applied.size()); ++k)
    if (run.applied[static_cast<size_t>(k)] < 1.0) return k - reversal;
  return -1;
}

TEST(Pid, BackCalculationLeavesSaturationPromptlyAfterReversal) {
  const PidGains g{1.0, 10.0, 0.0, 0.0};  // Ti = 0.1 s, tracking time = Ti
  const double saturated_s = 5.0;
  const long reversal = std::lround(saturated_s / kTs);

  const auto aw = run_saturating_loop(g, true, saturated_s, 30.0);
  const auto wound = run_saturating_loop(g, false, saturated_s, 30.0);

  // Both loops really saturate for the whole first phase.
  for (long k = 100; k < reversal; ++k) {
    ASSERT_EQ(aw.applied[static_cast<size_t>(k)], 1.0) << k;
    ASSERT_EQ(wound.applied[static_cast<size_t>(k)], 1.0) << k;
  }
  // With back-calculation the integrator tracks the limit: with Tt = Ti it settles at the
  // clamp value (1 V); without it, it integrates ki e T = 10 * 4 * 5 = 200.
  EXPECT_NEAR(aw.integral[static_cast<size_t>(reversal - 1)], 1.0, 0.05);
  EXPECT_GT(wound.integral[static_cast<size_t>(reversal - 1)], 150.0);

  const long t_aw = samples_to_leave_saturation(aw, reversal);
  const long t_wound = samples_to_leave_saturation(wound, reversal);
  // Back-calculation: the integral (1) plus kp e (-1) is already below the limit: a few samples.
  ASSERT_GE(t_aw, 0);
  EXPECT_LE(t_aw, 10);
  // Wound up: the integral must unwind 200 -> ~1 at ki |e| = 10 per second: ~20 s.
  ASSERT_TRUE(t_wound < 0 || t_wound > 1000) << t_wound;
  EXPECT_TRUE(t_wound < 0 || t_wound > 100 * std::max(t_aw, 1L));
}

TEST(Pid, BackCalculationWithDerivativeAndFixedTrackingTime) {
  // With a fixed tracking time the integrator settles where ki e = (unclamped - applied) / Tt.
  const PidGains g{2.0, 20.0, 0.02, 0.004};
  const double Tt = 0.05;
  Pid pid(g, kTs, Tt);
  const double e = 3.0;
  for (int k = 0; k < 20000; ++k) {
    const double c = pid.output(e);
    pid.commit(e, c, 1.0);  // output clamped at 1
  }
  // Fixed point: ki Ts e + (Ts/Tt)(1 - kp e - I) = 0  ->  I = 1 - kp e + ki Tt e.
  // 20000 samples = 400 Tt: converged to rounding.
  EXPECT_NEAR(pid.integral(), 1.0 - 2.0 * e + 20.0 * Tt * e, 1e-9);
}

TEST(Pid, AlignMakesTheNextOutputEqualTheTarget) {
  Pid pid({2.0, 5.0, 0.1, 0.01}, kTs);
  double e = 0.0;
  for (int k = 0; k < 200; ++k) {  // build up integral and derivative state
    e = std::sin(0.05 * k) * 3.0;
    const double c = pid.output(e);
    pid.commit(e, c, c);
  }
  for (double target : {-40.0, 0.0, 17.25, 500.0}) {
    const double e_now = e + 0.7;  // an error different from the last committed one
    pid.align(e_now, target);
    // output = kp e + I + kd D with I = target - kp e - kd D: exact up to rounding of |terms|.
    EXPECT_NEAR(pid.output(e_now), target, 1e-12 * (1.0 + std::abs(target)));
    EXPECT_NEAR(pid.output(e_now), target, 1e-12 * (1.0 + std::abs(target)));  // output() is idempotent
  }
}

TEST(Pid, RuntimeMatchesItsTransferFunction) {
  // pid_transfer_function is documented as exactly what Pid runs (when not clamped).
  for (const PidGains& g : {PidGains{1.5, 30.0, 0.0, 0.0}, PidGains{0.8, 12.0, 0.01, 0.002},
                            PidGains{0.0, 50.0, 0.0, 0.0}, PidGains{3.0, 0.0, 0.05, 0.001}}) {
    Pid pid(g, kTs);
    LtiFilter ref(realize(pid_transfer_function(g, kTs)));
    for (int k = 0; k < 3000; ++k) {
      const double e = std::sin(0.013 * k) + 0.5 * std::cos(0.17 * k) + (k == 10 ? 2.0 : 0.0);
      const double c = pid.output(e);
      pid.commit(e, c, c);
      const double expected = ref.step(e);
      // Two different summation orders of the same recursion; values O(100): 1e-9 absolute.
      ASSERT_NEAR(c, expected, 1e-9) << "k=" << k << " kp=" << g.kp << " ki=" << g.ki << " kd=" << g.kd;
    }
  }
}

TEST(Pid, ResetAndSetGains) {
  Pid pid({1.0, 100.0, 0.0, 0.0}, kTs);
  for (int k = 0; k < 10; ++k) pid.commit(1.0, pid.output(1.0), pid.output(1.0));
  EXPECT_NEAR(pid.integral(), 10 * 100.0 * kTs, 1e-12);
  pid.set_gains({2.0, 1.0, 0.0, 0.0});
  EXPECT_EQ(pid.gains().kp, 2.0);
  EXPECT_NEAR(pid.integral(), 1.0, 1e-12);  // set_gains keeps the integral (bumpless at e = 0)
  pid.reset();
  EXPECT_EQ(pid.integral(), 0.0);
  EXPECT_EQ(pid.output(0.5), 1.0);  // kp e only
}

}  // namespace
}  // namespace pvcgel::control
