// The diagnosis's variable projection (control/diagnosis/fit_problem.hpp): the nuisance parameters that
// enter linearly (gain, offset, G's start state per recording) are solved exactly, only over the fit
// samples, and the gain stays inside its tolerance.
#include "control/diagnosis/fit_problem.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace pvcgel::control::diagnosis::detail {
namespace {

constexpr double Ts = 1e-3;

/// u(t) of a 12 s multisine around 300 V.
Series drive() {
  Series s;
  s.sample_time_s = Ts;
  for (size_t k = 0; k < 12000; ++k) {
    const double t = static_cast<double>(k) * Ts;
    s.t_s.push_back(t);
    s.u_V.push_back(300.0 + 100.0 * std::sin(2 * M_PI * 0.4 * t) + 40.0 * std::sin(2 * M_PI * 2.3 * t + 1.0));
  }
  return s;
}

/// What a rig of the nominal model gives for `s.u_V`, at rest at `rest_V` before the first sample, seen
/// through a sensor with `gain` and `offset_um`. No I/O delay: with one, the rest voltage would also drive
/// the first sample, which is not a free response of G.
std::vector<double> rig_output(const HammersteinModel& m, const Series& s, double rest_V, double gain, double offset_um) {
  AugmentedPlant plant(m, 0, Ts, std::span<const Effect>{});
  auto y = plant.simulate(s.u_V, rest_V);
  for (double& v : y) v = gain * v + offset_um;
  return y;
}

struct Projection : ::testing::Test {
  HammersteinModel model = paper_model(2);
  DiagnosisOptions options;
  std::vector<Series> data{drive(), drive()};
  std::vector<std::vector<char>> held_out;

  void SetUp() override {
    // Two recordings of one rig: each starts off the rest the analysis assumes (at its first command),
    // each sensor with its own offset; one gain (inside the 0.8..1.25 tolerance).
    data[0].y_um = rig_output(model, data[0], 120.0, 1.1, 3.0);
    data[1].y_um = rig_output(model, data[1], 520.0, 1.1, -2.0);
    for (const auto& s : data) held_out.push_back(held_out_mask(s.u_V.size(), Ts, options));
  }
  Prediction project(Problem& p) {
    p.set_delay(0.0);
    p.set_initial({data[0].u_V.front(), data[1].u_V.front()});
    return p.predict({}, Nominal{}, true);
  }
};

TEST_F(Projection, GainOffsetAndEachRecordingsStartStateAreSolvedExactly) {
  Problem p(model, data, held_out, options);
  const auto pred = project(p);
  EXPECT_NEAR(pred.gain, 1.1, 1e-6);
  // G's free response decays, so each offset is the sensor's alone.
  EXPECT_NEAR(pred.offset_um[0], 3.0, 1e-4);
  EXPECT_NEAR(pred.offset_um[1], -2.0, 1e-4);
  for (size_t r = 0; r < data.size(); ++r) {
    double worst = 0.0;
    for (size_t k = 0; k < data[r].y_um.size(); ++k) worst = std::max(worst, std::abs(pred.y[r][k] - data[r].y_um[k]));
    EXPECT_LT(worst, 1e-6) << "recording " << r;  // held-out samples too: the projection extrapolates exactly
  }
  // The premise: without the start state's modes the first samples would be far off.
  double start_error = 0.0;
  AugmentedPlant plant(model, 0, Ts, std::span<const Effect>{});
  const auto y0 = plant.simulate(data[0].u_V, data[0].u_V.front());
  for (size_t k = 0; k < 100; ++k) start_error = std::max(start_error, std::abs(1.1 * y0[k] + 3.0 - data[0].y_um[k]));
  EXPECT_GT(start_error, 1.0);
}

TEST_F(Projection, OnlyTheFitSamplesAreFitted) {
  // A large error confined to the held-out samples moves nothing the projection fits.
  for (size_t k = 0; k < data[0].y_um.size(); ++k)
    if (held_out[0][k]) data[0].y_um[k] += 50.0;
  Problem p(model, data, held_out, options);
  const auto pred = project(p);
  EXPECT_NEAR(pred.gain, 1.1, 1e-6);
  EXPECT_NEAR(pred.offset_um[0], 3.0, 1e-4);
  EXPECT_LT(p.residual({}, Nominal{}).norm(), 1e-5);
}

TEST_F(Projection, AGainBeyondTheToleranceStopsAtItsBound) {
  for (auto& s : data)
    for (double& y : s.y_um) y *= 2.0;  // gain 2.2 in all
  Problem p(model, data, held_out, options);
  const auto pred = project(p);
  EXPECT_DOUBLE_EQ(pred.gain, gain_bounds(options).second);
  EXPECT_GT(p.residual({}, Nominal{}).norm(), 1.0);  // the rest of the gain is an error left to explain
}

TEST_F(Projection, ANegativeAddedTermLeavesFIncreasingPastTheControllersRangeWithRoomToWrite) {
  // The paper's n = 3 f turns over at 862 V; a controller up to 845 V (2% below, as ident writes it). The
  // largest negative next term the refit may add keeps f increasing 1% past 845 V: a fit that converged onto
  // a turnover at 845 V itself was refused by pvcgeld once its file's ten digits had moved it inside.
  model = paper_model(3);
  options.f_increasing_up_to_V = 845.0;
  options.f_increasing_margin = 1.0;  // the controller's range decides, not twice the recorded 440 V
  Problem p(model, data, held_out, options);
  const double c = p.next_coefficient(-options.poly_next_tolerance);
  ASSERT_LT(c, 0.0);
  const auto f = refit_model(model, 1.0, 1.0, c).f;
  EXPECT_FALSE(f.first_turnover(1.01 * 845.0).has_value());
  const auto turn = f.first_turnover(1000.0);
  ASSERT_TRUE(turn.has_value());
  EXPECT_LT(*turn, 1.02 * 845.0);  // the limit, not far inside it
}

TEST(SlewLimitStart, ADriveAtRestSlewsFromWhereTheActuatorWasNotFromTheFirstCommand) {
  // A rig left at rest at 480 V whose recording's commands start at 334 V (a closed loop from a charged
  // start): its 200 V/s amplifier slews down from 480 V for 0.7 s. (The rest the first samples imply is
  // looked for within 20% of the recorded commands' span beyond them: up to 496 V here.)
  const HammersteinModel model = paper_model(2);
  const DiagnosisOptions options;
  Series s = drive();
  Effect slew{EffectKind::slew_limit};
  slew.p[0] = 200.0;  // slew_rate_V_per_s; analog
  AugmentedPlant rig(model, 0, Ts, std::span<const Effect>(&slew, 1));
  s.y_um = rig.simulate(s.u_V, 480.0);
  const std::vector<Series> data{s};
  const std::vector<std::vector<char>> held_out{held_out_mask(s.u_V.size(), Ts, options)};
  Problem p(model, data, held_out, options);
  p.set_delay(0.0);
  p.set_initial({s.u_V.front()});  // the start the nominal model chose: its G modes absorb the rest
  const auto worst_error = [&] {
    const auto pred = p.predict(std::vector<Effect>{slew}, Nominal{}, true);
    double worst = 0.0;
    for (size_t k = 0; k < s.y_um.size(); ++k) worst = std::max(worst, std::abs(pred.y[0][k] - s.y_um[k]));
    return worst;
  };
  EXPECT_GT(worst_error(), 5.0);  // the drive slewing from the first command is microns off during the start
  p.set_drive_at_rest({1});
  EXPECT_LT(worst_error(), 0.05);  // the first samples' line puts the rest within a fraction of a volt
  // Only a slew limit's drive moves: the nominal alone starts where the analysis chose.
  const auto nominal = p.predict({}, Nominal{}, true);
  p.set_drive_at_rest({});
  EXPECT_EQ(p.predict({}, Nominal{}, true).y, nominal.y);
}

TEST(ModelDisplacement, TheSaturationsKneeRangeCoversTheNominalsDisplacementBeforeTheRefitsGain) {
  // A recorded stroke of 75..125 um read by a refit of gain 0.27 and offset 8 um (independent seed 137's
  // case043, a widened refit): the nominal's own displacement, where the knee acts, runs 248..433 um.
  DataScale scale;
  scale.y_min_um = 70.0, scale.y_max_um = 132.0;
  const auto before = parameter_specs(EffectKind::saturation, scale);
  EXPECT_LT(before[0].upper, 300.0);  // the knee's bound from the recorded stroke alone: 264 um
  Prediction refit;
  refit.gain = 0.27;
  refit.offset_um = {8.0};
  refit.y = {{75.0, 100.0, 125.0}};
  cover_model_displacement(scale, refit);
  EXPECT_NEAR(scale.model_y_min_um, (75.0 - 8.0) / 0.27, 1e-9);
  EXPECT_NEAR(scale.model_y_max_um, (125.0 - 8.0) / 0.27, 1e-9);
  EXPECT_EQ(scale.y_max_um, 132.0);  // the other effects keep the recorded scale
  const auto knee = parameter_specs(EffectKind::saturation, scale)[0];
  EXPECT_GE(knee.upper, 2.0 * scale.model_y_max_um);
  // Starts near the top of that displacement, where a stroke limit a nominal leaves bends it.
  EXPECT_TRUE(std::any_of(knee.starts.begin(), knee.starts.end(),
                          [&](double k) { return k > 0.75 * scale.model_y_max_um && k < scale.model_y_max_um; }));
  EXPECT_EQ(parameter_specs(EffectKind::drift, scale)[0].upper, 132.0);  // a drift's offset_um bound: the recorded y_abs
}

TEST(WanderingDrift, TheSplineFollowsASlowWanderThroughTheHeldOutBlocksAndMeasuresItsSize) {
  // 60 s: six 10 s blocks, the last 3 s of each held out. The wander is smooth on the 10 s scale (periods
  // of 90 s and 60 s, 1 um), as a thermal drift; a cubic spline knotted every 10 s follows it to ~0.01 um
  // (a 20 s period would leave ~0.4 um: the spline is for wander slower than the blocks).
  const HammersteinModel model = paper_model(2);
  DiagnosisOptions options;
  Series s;
  s.sample_time_s = Ts;
  std::vector<double> wander;
  for (size_t k = 0; k < 60000; ++k) {
    const double t = static_cast<double>(k) * Ts;
    s.t_s.push_back(t);
    s.u_V.push_back(300.0 + 100.0 * std::sin(2 * M_PI * 0.4 * t) + 40.0 * std::sin(2 * M_PI * 2.3 * t + 1.0));
    wander.push_back(std::sin(2 * M_PI * t / 90.0) + 0.5 * std::sin(2 * M_PI * t / 60.0 + 1.0));
  }
  s.y_um = rig_output(model, s, s.u_V.front(), 1.0, 0.0);
  for (size_t k = 0; k < s.y_um.size(); ++k) s.y_um[k] += wander[k];
  const std::vector<Series> data{s};
  const std::vector<std::vector<char>> held_out{held_out_mask(s.u_V.size(), Ts, options)};
  Problem p(model, data, held_out, options);
  p.set_delay(0.0);
  p.set_initial({s.u_V.front()});
  const Effect ramp{EffectKind::drift, {}}, wanders{EffectKind::drift, {0.0, 0.0, 0.0, 0.0, 1.0}};
  const auto without = p.predict({&ramp, 1}, Nominal{}, true);
  const auto with = p.predict({&wanders, 1}, Nominal{}, true);
  const auto e_without = errors_of(data, without.y, held_out), e_with = errors_of(data, with.y, held_out);
  EXPECT_GT(e_without.rmse_validation_um, 0.3);
  EXPECT_LT(e_with.rmse_validation_um, 0.03);  // interpolated across each held-out 3 s
  EXPECT_EQ(without.wander_um_per_sqrt_s, 0.0);
  // Its size: the RMS change of the true wander from knot to knot (every 10 s, and the last sample), over
  // sqrt(10 s).
  double sum = 0.0;
  for (size_t k = 10000; k <= 60000; k += 10000) sum += std::pow(wander[std::min<size_t>(k, 59999)] - wander[k - 10000], 2);
  const double truth = std::sqrt(sum / 6.0 / 10.0);
  EXPECT_NEAR(with.wander_um_per_sqrt_s, truth, 0.15 * truth);
}

}  // namespace
}  // namespace pvcgel::control::diagnosis::detail
