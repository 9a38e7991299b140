// Alignment as nuisance (control/diagnosis/alignment.cpp): delay, start state and offset are estimated,
// not blamed on an effect.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "control/diagnosis/diagnosis.hpp"
#include "tests/control/diagnosis/diagnosis_test_rig.hpp"

namespace pvcgel::control::diagnosis {
namespace {

using testing_rig::recording;
using testing_rig::Ts;

TEST(Alignment, AnUndeclaredDelayAStartNotAtRestAndAnOffsetAreNuisanceNotEffects) {
  // Truth: 2 samples of I/O delay, a sensor offset of 0.4 um, and a start 100 V away from rest.
  Series s = recording({}, 0.0);
  AugmentedPlant truth(paper_model(3), 2, Ts, Effect{});
  truth.reset_steady_state(s.u_V[0] - 100.0);
  std::mt19937_64 rng(9);
  std::normal_distribution<double> N(0.0, 0.05);
  for (size_t k = 0; k < s.u_V.size(); ++k) {
    s.y_um[k] = truth.output() + 0.4 + N(rng);
    truth.apply(s.u_V[k]);
  }
  DiagnosisOptions o;
  o.io_delay_declared = false;
  const auto r = diagnose(paper_model(3), {s}, o);
  EXPECT_EQ(r.verdict, "none") << r.explanation;
  EXPECT_NEAR(r.alignment.io_delay_samples, 2.0, 0.1);
  EXPECT_FALSE(r.alignment.declared);
  EXPECT_NEAR(r.alignment.offset_um[0], 0.4, 0.05);
  // A silent file takes the estimate: there is no declared delay to hold a longer one against.
  EXPECT_FALSE(r.alignment.longer_delay);
  EXPECT_EQ(r.alignment.declared_delay_excess_noise_variances, 0.0);
  // Declared as 1: the file is contradicted, and the extra sample is a delay effect.
  const auto d = diagnose(paper_model(3), {s});
  EXPECT_NE(d.alignment.note.find("declares io_delay_samples = 1"), std::string::npos) << d.alignment.note;
  EXPECT_EQ(d.verdict, "delay") << d.explanation;
  // The search's best longer delay, against the nuisance-only refit at the declared one: far beyond chance.
  ASSERT_TRUE(d.alignment.longer_delay);
  EXPECT_EQ(d.alignment.longer_delay->samples, 2);
  EXPECT_GT(d.alignment.declared_delay_excess_noise_variances, 25.0);
}

TEST(Alignment, TheRestBeforeTheFirstSampleIsFoundWhenNeitherTheFirstCommandNorTheFirstLevelGivesIt) {
  // A closed loop's start at 100 Hz: the rig rests at 300 V, the controller's first command is 40 V above
  // it (its gain times the first error), and the sensor reads 8 um low. The rest at u[0] misses the two
  // samples of delayed rest voltage; the rest the first samples imply misses by the offset.
  const double Ts_100Hz = 0.01, rest_V = 300.0;
  Series s;
  s.sample_time_s = Ts_100Hz;
  for (size_t k = 0; k < 3000; ++k) {
    const double t = static_cast<double>(k) * Ts_100Hz;
    s.t_s.push_back(t);
    s.u_V.push_back(rest_V + 40.0 * std::exp(-t) + 60.0 * std::sin(2 * M_PI * 0.5 * t) + 20.0 * std::sin(2 * M_PI * 2.3 * t));
  }
  AugmentedPlant truth(paper_model(3), 2, Ts_100Hz, Effect{});
  truth.reset_steady_state(rest_V);
  std::mt19937_64 rng(12);
  std::normal_distribution<double> N(0.0, 0.05);
  for (double u : s.u_V) {
    s.y_um.push_back(truth.output() - 8.0 + N(rng));
    truth.apply(u);
  }
  DiagnosisOptions o;
  o.io_delay_samples = 2;
  const auto r = diagnose(paper_model(3), {s}, o);
  std::printf("rest found %.2f V (truth %.0f V, u[0] %.0f V), worst 1 s window %.3f x the noise variance (threshold %.3f)\n",
              r.alignment.initial_V.empty() ? NAN : r.alignment.initial_V[0], rest_V, s.u_V[0],
              r.none_test.worst_window_ratio, r.none_test.window_threshold);
  EXPECT_EQ(r.verdict, "none") << r.explanation << " (worst window " << r.none_test.worst_window_ratio << " x the noise, "
                               << "threshold " << r.none_test.window_threshold << ")";
  ASSERT_EQ(r.alignment.initial_V.size(), 1u);
  EXPECT_NEAR(r.alignment.initial_V[0], rest_V, 2.0);
  EXPECT_NEAR(r.alignment.offset_um[0], -8.0, 0.05);
}

}  // namespace
}  // namespace pvcgel::control::diagnosis
