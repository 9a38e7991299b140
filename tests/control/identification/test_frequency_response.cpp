#include "control/identification/frequency_response.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace pvcgel::control::identification {
namespace {

constexpr double kPi = std::numbers::pi;

struct Synthetic {
  std::vector<double> t, u, y;
};

// u = B + A sin(w t); y = dc + g A sin(w t + phi) + h2 sin(2 w t + 0.3) + h3 sin(3 w t - 1) + noise.
Synthetic make(double A, double B, double f, double g, double phi, double duration, double noise = 0.0,
               double Ts = 1e-3) {
  Synthetic s;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n01;
  const double w = 2 * kPi * f;
  for (size_t k = 0; k < static_cast<size_t>(duration / Ts); ++k) {
    const double t = static_cast<double>(k) * Ts;
    s.t.push_back(t);
    s.u.push_back(B + A * std::sin(w * t));
    s.y.push_back(42.0 + g * A * std::sin(w * t + phi) + 3.0 * std::sin(2 * w * t + 0.3) +
                  1.5 * std::sin(3 * w * t - 1.0) + noise * n01(rng));
  }
  return s;
}

TEST(IdentFrequencyResponse, RecoversAmplitudePhaseDcAndHarmonicsOfASyntheticSine) {
  // 2.3 Hz: 434.78 samples per period, so the window is not a whole number of samples.
  const auto s = make(300.0, 450.0, 2.3, 0.25, -0.7, 14.0);
  ExtractionOptions o;
  o.settle_s = 2.0;
  const auto p = extract_frequency_response(s.t, s.u, s.y, o, "synthetic");
  ASSERT_TRUE(p.valid) << p.problem;
  EXPECT_NEAR(p.amplitude_V, 300.0, 1e-6);
  EXPECT_NEAR(p.bias_V, 450.0, 1e-6);
  EXPECT_NEAR(p.frequency_Hz, 2.3, 1e-9);
  EXPECT_NEAR(std::abs(p.response), 0.25, 1e-9);
  EXPECT_NEAR(std::arg(p.response), -0.7, 1e-9);
  EXPECT_NEAR(p.dc_um, 42.0, 1e-6);
  ASSERT_GE(p.harmonic_um.size(), 3u);
  EXPECT_NEAR(p.harmonic_um[0], 0.25 * 300.0, 1e-6);
  EXPECT_NEAR(p.harmonic_um[1], 3.0, 1e-6);
  EXPECT_NEAR(p.harmonic_um[2], 1.5, 1e-6);
  EXPECT_EQ(p.periods, 27);  // floor(12 s * 2.3 Hz)
  EXPECT_LT(p.response_sigma, 1e-9);
}

TEST(IdentFrequencyResponse, UncertaintyReflectsTheNoise) {
  const auto s = make(300.0, 450.0, 1.0, 0.25, -0.7, 30.0, 2.0);
  ExtractionOptions o;
  o.settle_s = 0.0;
  const auto p = extract_frequency_response(s.t, s.u, s.y, o);
  ASSERT_TRUE(p.valid) << p.problem;
  // White noise sigma 2 um over N = 30000 samples: sigma of |Y1| is sigma sqrt(2/N) = 0.0163 um,
  // i.e. 5.4e-5 in the response. The per-period spread must see that order of magnitude.
  const double expected = 2.0 * std::sqrt(2.0 / 30000.0) / 300.0;
  EXPECT_GT(p.response_sigma, 0.5 * expected);
  EXPECT_LT(p.response_sigma, 2.0 * expected);
  EXPECT_LT(std::abs(p.response - std::polar(0.25, -0.7)), 4.0 * expected);
}

TEST(IdentFrequencyResponse, FlagsTooFewPeriods) {
  const auto s = make(300.0, 450.0, 0.1, 0.25, -0.7, 25.0);  // 15 s after settling: 1.5 periods
  const auto p = extract_frequency_response(s.t, s.u, s.y, ExtractionOptions{});
  EXPECT_FALSE(p.valid);
  EXPECT_NE(p.problem.find("too few periods"), std::string::npos) << p.problem;
  const auto q = make(300.0, 450.0, 0.1, 0.25, -0.7, 35.0);  // 2 whole periods: still fewer than 3
  const auto pq = extract_frequency_response(q.t, q.u, q.y, ExtractionOptions{});
  EXPECT_FALSE(pq.valid);
  EXPECT_NE(pq.problem.find("only 2 whole period"), std::string::npos) << pq.problem;
}

TEST(IdentFrequencyResponse, FlagsAClippedInput) {
  auto s = make(400.0, 700.0, 1.0, 0.25, -0.7, 20.0);  // asks for 1100 V
  for (auto& u : s.u) u = std::clamp(u, 0.0, 1000.0);  // the amplifier clips
  const auto p = extract_frequency_response(s.t, s.u, s.y, ExtractionOptions{});
  EXPECT_FALSE(p.valid);
  EXPECT_NE(p.problem.find("clipped at 1000"), std::string::npos) << p.problem;

  auto low = make(400.0, 300.0, 1.0, 0.25, -0.7, 20.0);
  for (auto& u : low.u) u = std::max(u, 0.0);
  const auto pl = extract_frequency_response(low.t, low.u, low.y, ExtractionOptions{});
  EXPECT_FALSE(pl.valid);
  EXPECT_NE(pl.problem.find("clipped at 0"), std::string::npos) << pl.problem;
}

TEST(IdentFrequencyResponse, FlagsNoOscillationAndNonFiniteData) {
  auto s = make(300.0, 450.0, 1.0, 0.25, -0.7, 20.0);
  auto flat = s;
  for (auto& u : flat.u) u = 450.0;
  EXPECT_FALSE(extract_frequency_response(flat.t, flat.u, flat.y, ExtractionOptions{}).valid);
  s.y[15000] = NAN;
  const auto p = extract_frequency_response(s.t, s.u, s.y, ExtractionOptions{});
  EXPECT_FALSE(p.valid);
  EXPECT_NE(p.problem.find("non-finite"), std::string::npos);
}

TEST(IdentFrequencyResponse, SineEstimateFindsFrequencyWithoutMetadata) {
  const auto s = make(333.0, 512.0, 0.4641588834, 0.1, 0.0, 30.0);
  const auto e = estimate_sine(s.t, s.u, 0, s.t.size());
  ASSERT_TRUE(e.found);
  EXPECT_NEAR(e.frequency_Hz, 0.4641588834, 1e-9);
  EXPECT_NEAR(e.amplitude_V, 333.0, 1e-6);
  EXPECT_NEAR(e.bias_V, 512.0, 1e-6);
  EXPECT_NEAR(e.phase_rad, 0.0, 1e-6);
  EXPECT_LT(e.residual_rms_V, 1e-6);
}

}  // namespace
}  // namespace pvcgel::control::identification
