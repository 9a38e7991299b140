#include "tools/paper_bench.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <numbers>

#include "control/polynomial_inverse.hpp"

namespace pvcgel::tools {
namespace {

using control::ControllerMode;

// One shortened run of the paper comparison, shared by the tests below (it is the
// expensive part: 4 references x 4 modes x 40 s at 1 kHz).
const PaperBenchResult& bench() {
  static const PaperBenchResult result = [] {
    PaperBenchOptions o;
    o.duration_s = 40.0;
    o.settle_s = 15.0;
    return run_paper_bench(o);
  }();
  return result;
}

double mean_of(const ReferenceResult& r, ControllerMode m) {
  return r.modes[static_cast<size_t>(m)].errors.mean_abs_um;
}

TEST(PaperBench, RunsEveryReferenceUnderEveryMode) {
  const auto& r = bench();
  ASSERT_EQ(r.references.size(), control::kPaperReferenceNames.size());
  // The sensor noise is N(0, 0.05 um): mean |noise| = 0.05 sqrt(2/pi) = 0.0399 um (quantisation
  // at 0.01 um changes it by < 1%); averaged over 16 runs of 25000 samples, 5% is > 10 sigma.
  EXPECT_NEAR(r.noise_floor_um, 0.05 * std::sqrt(2.0 / std::numbers::pi), 0.05 * 0.0399);
  std::printf("noise floor (mean |y - y_true|): %.4f um\n", r.noise_floor_um);
  std::printf("%-7s %10s %12s %16s %19s\n", "ref", "pid", "inverse_pid", "inverse_pid_dob", "inverse_pid_dob_ff");
  for (size_t i = 0; i < r.references.size(); ++i) {
    const auto& rr = r.references[i];
    EXPECT_EQ(rr.name, control::kPaperReferenceNames[i]);
    for (size_t m = 0; m < 4; ++m) {
      EXPECT_EQ(rr.modes[m].mode, control::kAllModes[m]);
      EXPECT_TRUE(std::isfinite(rr.modes[m].errors.mean_abs_um));
      EXPECT_GT(rr.modes[m].errors.mean_abs_um, 0.0);
      EXPECT_TRUE(rr.modes[m].margins.stable());
      EXPECT_EQ(rr.modes[m].errors.saturated_samples, 0);  // references stay far inside 0..1000 V
    }
    std::printf("%-7s %10.4f %12.4f %16.4f %19.4f   (mean |e|, um)\n", rr.name.c_str(),
                mean_of(rr, ControllerMode::pid), mean_of(rr, ControllerMode::inverse_pid),
                mean_of(rr, ControllerMode::inverse_pid_dob), mean_of(rr, ControllerMode::inverse_pid_dob_ff));
  }
  std::cout << std::flush;
}

TEST(PaperBench, FeedforwardModeReachesTheNoiseFloor) {
  const auto& r = bench();
  for (const auto& rr : r.references) {
    const double ff = mean_of(rr, ControllerMode::inverse_pid_dob_ff);
    const double pid = mean_of(rr, ControllerMode::pid);
    // The acceptance criterion: within twice the sensor-noise floor.
    EXPECT_LE(ff, 2.0 * r.noise_floor_um) << rr.name;
    // At least a 4x reduction versus plain PID, measured. The measured error cannot go below
    // the noise floor, so this is only attainable where 0.25 x pid is above that floor; at
    // 0.1 Hz pid itself is already within 2x the floor (~0.074 um) and the same criterion is
    // applied to the error without sensor noise instead (below).
    if (0.25 * pid > r.noise_floor_um) {
      EXPECT_LT(ff, 0.25 * pid) << rr.name;
    } else {
      std::printf("%s: 4x measured reduction unattainable (0.25 x pid = %.4f um < noise floor %.4f um)\n",
                  rr.name.c_str(), 0.25 * pid, r.noise_floor_um);
    }
    const double ff_true = rr.modes[static_cast<size_t>(ControllerMode::inverse_pid_dob_ff)].errors.mean_abs_true_um;
    const double pid_true = rr.modes[static_cast<size_t>(ControllerMode::pid)].errors.mean_abs_true_um;
    std::printf("%s: mean |r - y_true|  ff %.4f um  pid %.4f um\n", rr.name.c_str(), ff_true, pid_true);
    EXPECT_LT(ff_true, 0.25 * pid_true) << rr.name;
  }
  // Where the paper's PID error is well above the noise (0.5 Hz, 1 Hz, multi), the measured
  // criterion must have been applied, so the check above is not vacuous.
  int measured = 0;
  for (const auto& rr : r.references) measured += 0.25 * mean_of(rr, ControllerMode::pid) > r.noise_floor_um;
  EXPECT_GE(measured, 3);
}

TEST(PaperBench, InverseCompensationBeatsPid) {
  for (const auto& rr : bench().references)
    EXPECT_LT(mean_of(rr, ControllerMode::inverse_pid), mean_of(rr, ControllerMode::pid)) << rr.name;
}

TEST(PaperBench, DisturbanceObserverStaysCloseToInversePid) {
  // Known and documented: on this rig the truth's small-signal gain is ~27% above the n = 2
  // model, which gives inverse_pid that much extra loop gain; the DOB removes it, so
  // inverse_pid_dob is not better than inverse_pid here. In this bandwidth-limited regime
  // the error scales roughly with 1/loop gain, so the DOB's error may exceed inverse_pid's by
  // about that gain ratio; 10% on top covers phase effects (measured ratios: 1.22..1.31).
  const PaperBenchOptions o;
  const auto model_f = o.model.f, truth_f = o.rig.truth.f;
  const double u_op = control::PolynomialInverse(model_f, 0.0, 1000.0)(100.0 / o.model.G.dc_gain());
  const double gain_ratio = truth_f.derivative(u_op) / model_f.derivative(u_op);
  std::printf("truth/model small-signal gain at %.1f V: %.3f\n", u_op, gain_ratio);
  EXPECT_NEAR(gain_ratio, 1.27, 0.02);  // the documented 27%
  for (const auto& rr : bench().references) {
    const double inv = mean_of(rr, ControllerMode::inverse_pid);
    const double dob = mean_of(rr, ControllerMode::inverse_pid_dob);
    std::printf("%s: inverse_pid_dob / inverse_pid = %.3f\n", rr.name.c_str(), dob / inv);
    EXPECT_LE(dob, 1.1 * gain_ratio * inv) << rr.name;
  }
}

TEST(PaperBench, OnARigEqualToTheModelTheObserverChangesNothing) {
  // bandwidth_only_mean_um runs each controller on a rig that is exactly the model, without
  // noise: the DOB then estimates d = 0 (to rounding), so inverse_pid and inverse_pid_dob run the
  // same loop, and the feedforward mode, an exact inverse of the model, tracks exactly.
  for (const auto& rr : bench().references) {
    const auto bw = [&](ControllerMode m) { return rr.modes[static_cast<size_t>(m)].bandwidth_only_mean_um; };
    std::printf("%s bandwidth-only: pid %.4f  inverse_pid %.4f  inverse_pid_dob %.4f  ff %.2e um\n", rr.name.c_str(),
                bw(ControllerMode::pid), bw(ControllerMode::inverse_pid), bw(ControllerMode::inverse_pid_dob),
                bw(ControllerMode::inverse_pid_dob_ff));
    EXPECT_GT(bw(ControllerMode::inverse_pid), 0.01) << rr.name;  // a real, bandwidth-limited error
    // d_hat ~ 1e-10 of v: the two runs differ by rounding only.
    EXPECT_NEAR(bw(ControllerMode::inverse_pid_dob), bw(ControllerMode::inverse_pid), 1e-6 * bw(ControllerMode::inverse_pid))
        << rr.name;
    // Exact feedforward on the exact model from its steady state: rounding-level error.
    EXPECT_LT(bw(ControllerMode::inverse_pid_dob_ff), 1e-6) << rr.name;
  }
}

TEST(PaperBench, ReportsAreConsistentWithTheResults) {
  PaperBenchOptions o;
  o.duration_s = 40.0;
  o.settle_s = 15.0;
  const auto& r = bench();
  const std::string table = format_table(r, o);
  const std::string json = to_json(r, o);
  for (const auto& name : control::kPaperReferenceNames) {
    EXPECT_NE(table.find(name), std::string::npos) << name;
    EXPECT_NE(json.find("\"" + name + "\""), std::string::npos) << name;
  }
  EXPECT_NE(json.find("\"noise_floor_um\""), std::string::npos);
  for (const auto& rr : r.references) {
    const bool holds = mean_of(rr, ControllerMode::inverse_pid_dob) < mean_of(rr, ControllerMode::inverse_pid) &&
                       mean_of(rr, ControllerMode::inverse_pid) < mean_of(rr, ControllerMode::pid);
    EXPECT_EQ(paper_ranking_holds(rr), holds) << rr.name;
  }
}

}  // namespace
}  // namespace pvcgel::tools
