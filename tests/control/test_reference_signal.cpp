#include "control/reference_signal.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace pvcgel::control {
namespace {

TEST(ReferenceSignal, PaperSinesAreY_r1) {
  for (const auto& [name, f] : {std::pair{"0.1Hz", 0.1}, std::pair{"0.5Hz", 0.5}, std::pair{"1Hz", 1.0}}) {
    const auto r = paper_reference(name);
    ASSERT_TRUE(r.has_value()) << name;
    EXPECT_EQ(r->n_tones, 1);
    EXPECT_DOUBLE_EQ(r->slowest_period_s(), 1.0 / f);
    for (double t : {0.0, 0.37, 1.9, 12.25}) {
      // y_r1 = 100 + 25 sin(2 pi f t); same expression, so equal to rounding.
      EXPECT_NEAR((*r)(t), 100.0 + 25.0 * std::sin(2.0 * std::numbers::pi * f * t), 1e-12) << name << " t=" << t;
    }
  }
}

TEST(ReferenceSignal, PaperMultiIsY_r2) {
  const auto r = paper_reference("multi");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->n_tones, 3);
  EXPECT_DOUBLE_EQ(r->slowest_period_s(), 10.0);
  for (double t : {0.0, 0.25, 3.3, 17.0}) {
    const double expected = (33.0 + 5.0 * std::sin(0.2 * std::numbers::pi * t)) + (33.0 + 7.0 * std::sin(std::numbers::pi * t)) +
                            (30.0 + 12.0 * std::sin(2.0 * std::numbers::pi * t));
    EXPECT_NEAR((*r)(t), expected, 1e-12) << t;
  }
}

TEST(ReferenceSignal, NamesAreCaseInsensitiveWithOptionalPrefix) {
  EXPECT_TRUE(paper_reference("PAPER-1HZ").has_value());
  EXPECT_TRUE(paper_reference("paper-multi").has_value());
  EXPECT_TRUE(paper_reference("0.5hz").has_value());
  EXPECT_FALSE(paper_reference("2Hz").has_value());
  EXPECT_FALSE(paper_reference("").has_value());
  EXPECT_FALSE(paper_reference("paper-").has_value());
  ASSERT_EQ(kPaperReferenceNames.size(), 4u);
  for (const auto& n : kPaperReferenceNames) EXPECT_TRUE(paper_reference(n).has_value()) << n;
}

TEST(ReferenceSignal, SegmentValuesAreTheOffsetThenEachTonesAmplitudeFrequencyAndPhase) {
  // The layout `pvcgel send paper` and the live view's reference button put on the wire.
  EXPECT_EQ(multisine_segment_values(*paper_reference("multi")),
            (std::vector<double>{96.0, 5.0, 0.1, 0.0, 7.0, 0.5, 0.0, 12.0, 1.0, 0.0}));
  EXPECT_EQ(multisine_segment_values(*paper_reference("1Hz")), (std::vector<double>{100.0, 25.0, 1.0, 0.0}));
  MultiSine hold;
  hold.offset_um = 42.0;
  EXPECT_EQ(multisine_segment_values(hold), std::vector<double>{42.0});
}

TEST(ReferenceSignal, HoldHasNoTones) {
  MultiSine hold;
  hold.offset_um = 42.0;
  EXPECT_EQ(hold(123.4), 42.0);
  EXPECT_EQ(hold.slowest_period_s(), 0.0);
}

}  // namespace
}  // namespace pvcgel::control
