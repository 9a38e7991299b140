#include "control/reference_feedforward.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <vector>

#include "control/reference_signal.hpp"

namespace pvcgel::control {
namespace {

TEST(ReferenceFeedforward, NominalModelOutputsExactlyTheReference) {
  // v_ff[k] = A/B r[k + r]: driving G_d (which includes the r samples of delay) with it gives
  // y[k] = r[k] on the nominal model, with no lag at all.
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, 1e-3, 1);
  ReferenceFeedforward ff(plant);
  ASSERT_EQ(ff.preview_samples(), 2);
  LtiFilter g(realize(plant.G_d));
  const auto multi = *paper_reference("multi");
  const double Ts = 1e-3;
  // Held at r(0) for the first second (so both filters' steady-state starts are consistent
  // with the history), then the paper's multi-sine.
  auto r = [&](long k) { return k < 1000 ? multi(0.0) : multi(static_cast<double>(k - 1000) * Ts); };
  ff.reset_steady_state(r(0));
  g.reset_steady_state(r(0) / model.G.dc_gain());
  double worst = 0.0, worst_one_sample_late = 0.0;
  for (long k = 0; k < 6000; ++k) {
    const double v = ff.step(r(k + ff.preview_samples()));
    EXPECT_EQ(ff.value(), v);
    const double y = g.step(v);
    worst = std::max(worst, std::abs(y - r(k)));
    if (k > 0) worst_one_sample_late = std::max(worst_one_sample_late, std::abs(y - r(k - 1)));
  }
  std::cout << "max |y - r| = " << worst << " um (vs. one sample late: " << worst_one_sample_late << " um)\n";
  // Exact inverse: only rounding remains (internal values ~1e3, through the inverse's slow
  // pole at z = e^{-0.896 Ts}, i.e. ~1e3 samples of memory): 1e-7 um. A timing error of one
  // sample would leave |dr/dt| Ts ~ 0.1 um.
  EXPECT_LT(worst, 1e-7);
  EXPECT_GT(worst_one_sample_late, 1e-2);
}

TEST(ReferenceFeedforward, ConstantReferenceNeedsTheStaticInput) {
  const auto model = paper_model(2);
  const auto plant = DiscretePlantModel::make(model.G, 1e-3, 1);
  ReferenceFeedforward ff(plant);
  ff.reset_steady_state(100.0);
  // (I - A) conditioned by the slow plant pole (~2e3): 1e-9 relative.
  for (int k = 0; k < 10; ++k) EXPECT_NEAR(ff.step(100.0), 100.0 / model.G.dc_gain(), 1e-9 * 850.0);
}

}  // namespace
}  // namespace pvcgel::control
