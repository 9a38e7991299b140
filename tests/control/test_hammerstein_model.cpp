#include "control/hammerstein_model.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "control/config_error.hpp"
#include "control/lti_filter.hpp"

namespace pvcgel::control {
namespace {

constexpr double kTs = 1e-3;

TEST(HammersteinModel, PaperModelsAreTheIdentifiedOnes) {
  EXPECT_EQ(paper_model(1).f.coefficients(), (std::vector<double>{1.3664}));
  EXPECT_EQ(paper_model(2).f.coefficients(), (std::vector<double>{0.1270, 1.3057e-5}));
  EXPECT_EQ(paper_model(3).f.coefficients(), (std::vector<double>{0.0721, 2.1307e-5, -1.7231e-11}));
  for (int n : {1, 2, 3}) {
    EXPECT_EQ(paper_model(n).G.num(), (std::vector<double>{1.15, 1.03}));
    EXPECT_EQ(paper_model(n).G.den(), (std::vector<double>{1.0, 17.11, 8.76}));
  }
  for (int n : {0, 4}) {
    try {
      (void)paper_model(n);
      FAIL() << n;
    } catch (const ConfigError& e) {
      EXPECT_EQ(e.key(), "model.poly");
    }
  }
}

TEST(DiscretePlantModel, PaperPlantHasTwoSamplesDelayAndAnExactInverse) {
  const auto G = paper_model(2).G;
  const auto m = DiscretePlantModel::make(G, kTs, 1);
  EXPECT_EQ(m.delay_samples, 2);  // one from the hold, one of I/O delay
  EXPECT_EQ(m.Ts_s, kTs);
  EXPECT_EQ(m.G_d.delay_samples(), 2);
  EXPECT_NEAR(m.G_d.dc_gain(), G.dc_gain(), 1e-10 * G.dc_gain());
  // The inverse is A/B normalised to a(0) = 1, and inverse * G_d = z^-2.
  EXPECT_EQ(m.inverse.a(0), 1.0);
  EXPECT_NEAR(m.inverse.dc_gain() * m.G_d.dc_gain(), 1.0, 1e-10);
  for (double w : {0.1, 10.0, 300.0, 3000.0}) {
    const auto prod = m.inverse.frequency_response(w, kTs) * m.G_d.frequency_response(w, kTs);
    const auto expected = std::polar(1.0, -2.0 * w * kTs);
    // Exact cancellation up to rounding of the polynomial evaluations.
    EXPECT_NEAR(std::abs(prod - expected), 0.0, 1e-9) << "w=" << w;
  }
  // Running the two filters in series reproduces the input two samples late.
  LtiFilter g(realize(m.G_d)), ginv(realize(m.inverse));
  std::vector<double> u(500);
  for (size_t k = 0; k < u.size(); ++k) u[k] = 300.0 + 50.0 * std::sin(0.02 * static_cast<double>(k));
  for (size_t k = 0; k < u.size(); ++k) {
    const double w = ginv.step(g.step(u[k]));
    if (k >= 2) {
      EXPECT_NEAR(w, u[k - 2], 1e-9 * 350.0) << k;  // inverse is stable: no error growth
    }
  }
}

TEST(DiscretePlantModel, IoDelayAddsWholeSamples) {
  const auto G = paper_model(2).G;
  for (int d : {0, 1, 3}) {
    const auto m = DiscretePlantModel::make(G, kTs, d);
    EXPECT_EQ(m.delay_samples, 1 + d);
    EXPECT_EQ(m.G_d.delay_samples(), 1 + d);
  }
}

void expect_key(const TransferFunction& G, double Ts, int delay, const std::string& key) {
  try {
    (void)DiscretePlantModel::make(G, Ts, delay);
    FAIL() << G.to_string() << " Ts=" << Ts << " delay=" << delay << " accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), key) << e.what();
    EXPECT_NE(std::string(e.what()).find(key), std::string::npos);
  }
}

TEST(DiscretePlantModel, RejectsBadPlantsNamingTheKey) {
  expect_key(TransferFunction({-1.15, 1.03}, {1.0, 17.11, 8.76}), kTs, 1, "model.G");  // RHP zero
  expect_key(TransferFunction({1.0}, {1.0, -1.0}), kTs, 1, "model.G");                 // unstable
  expect_key(TransferFunction({1.0, 0.0, 0.0}, {1.0, 1.0}), kTs, 1, "model.G");        // improper
  expect_key(TransferFunction({2.0, 1.0}, {1.0, 3.0}), kTs, 0, "model.io_delay_samples");  // biproper, no delay
  expect_key(paper_model(2).G, 0.0, 1, "loop.period_s");
  expect_key(paper_model(2).G, 1e-3, -1, "model.io_delay_samples");
  expect_key(paper_model(2).G, 1e-3, 9, "model.io_delay_samples");
  // Relative degree 3: ZOH sampling zeros tend to -2 +- sqrt(3); -3.73 is outside the unit circle.
  expect_key(TransferFunction({1.0}, {1.0, 3.0, 3.0, 1.0}), kTs, 1, "model.G");
}

TEST(DiscretePlantModel, RelativeDegreeTwoIsAccepted) {
  // Its ZOH sampling zero tends to -1 from inside the unit circle as Ts -> 0.
  const auto m = DiscretePlantModel::make(TransferFunction({1.0}, {1.0, 3.0, 2.0}), kTs, 1);
  EXPECT_EQ(m.delay_samples, 2);
  const auto z = DiscreteTransferFunction{m.inverse.a, Eigen::VectorXd::Ones(1)}.zeros();
  ASSERT_EQ(z.size(), 1);
  EXPECT_LT(std::abs(z(0)), 1.0);
  EXPECT_NEAR(z(0).real(), -1.0, 0.01);  // O(Ts) away from the limit
}

}  // namespace
}  // namespace pvcgel::control
