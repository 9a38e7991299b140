#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "daemon/setpoint_schedule.hpp"

using namespace pvcgel::daemon;
using Kind = SetpointSegment::Kind;
using Timing = SetpointSegment::Timing;

namespace {
SetpointSegment hold(double level, Timing timing, double start_s = 0.0, double duration_s = INFINITY) {
  SetpointSegment s;
  s.kind = Kind::hold;
  s.timing = timing;
  s.start_s = start_s;
  s.end_s = start_s + duration_s;
  s.values[0] = level;
  s.count = 1;
  return s;
}
SetpointSegment samples(std::initializer_list<double> v, double period_s, Timing timing, double start_s = 0.0) {
  SetpointSegment s;
  s.kind = Kind::samples;
  s.timing = timing;
  s.period_s = period_s;
  s.start_s = start_s;
  s.count = static_cast<int>(v.size());
  std::copy(v.begin(), v.end(), s.values.begin());
  s.end_s = start_s + s.count * period_s;
  return s;
}
}  // namespace

TEST(SetpointSchedule, SamplesInterpolateLinearlyAndAcrossContiguousPieces) {
  SetpointSchedule q;
  ASSERT_TRUE(q.add(samples({0, 10, 20}, 0.1, Timing::at, 1.0), 0.5, 0.0));
  ASSERT_TRUE(q.add(samples({40, 50}, 0.1, Timing::append), 0.5, 0.0));
  double v = 0;
  EXPECT_FALSE(q.value_at(0.9, v)) << "before the first sample nothing is defined";
  ASSERT_TRUE(q.value_at(1.05, v));
  EXPECT_NEAR(v, 5.0, 1e-9);
  ASSERT_TRUE(q.value_at(1.25, v));
  EXPECT_NEAR(v, 30.0, 1e-9) << "20 at 1.2 s, 40 at 1.3 s (the appended piece)";
  ASSERT_TRUE(q.value_at(1.35, v));
  EXPECT_NEAR(v, 45.0, 1e-9);
  EXPECT_NEAR(q.queued_until_s(), 1.5, 1e-12);
  EXPECT_FALSE(q.value_at(1.5, v)) << "the queue ran dry";
}

TEST(SetpointSchedule, ReplaceDropsWhatWasQueuedFromItsStart) {
  SetpointSchedule q;
  ASSERT_TRUE(q.add(hold(10, Timing::at, 0.0, 5.0), 0.0, 0.0));
  ASSERT_TRUE(q.add(hold(20, Timing::append, 0.0, 5.0), 0.0, 0.0));
  EXPECT_EQ(q.size(), 2);
  ASSERT_TRUE(q.add(hold(30, Timing::at, 2.0), 1.0, 10.0));
  EXPECT_EQ(q.size(), 2) << "the appended hold (from 5 s) is dropped, the first is cut at 2 s";
  double v = 0;
  ASSERT_TRUE(q.value_at(1.999, v));
  EXPECT_EQ(v, 10.0);
  ASSERT_TRUE(q.value_at(2.0, v));
  EXPECT_EQ(v, 30.0);
  ASSERT_TRUE(q.value_at(100.0, v));
  EXPECT_EQ(v, 30.0);
  q.advance(3.0);
  EXPECT_EQ(q.size(), 1);
}

TEST(SetpointSchedule, NowAndAppendMoveRelativeSegmentsToLoopTime) {
  SetpointSchedule q;
  ASSERT_TRUE(q.add(hold(5, Timing::now, 0.0, 1.0), 7.0, 0.0));
  double v = 0;
  EXPECT_FALSE(q.value_at(6.99, v));
  ASSERT_TRUE(q.value_at(7.5, v));
  EXPECT_EQ(v, 5.0);
  ASSERT_TRUE(q.add(hold(6, Timing::append, 0.0, 1.0), 7.2, 0.0));
  ASSERT_TRUE(q.value_at(8.5, v));
  EXPECT_EQ(v, 6.0);
  EXPECT_NEAR(q.queued_until_s(), 9.0, 1e-12);
}

TEST(SetpointSchedule, BlendIsARaisedCosineFromTheSetpointInForce) {
  SetpointSchedule q;
  auto s = hold(100, Timing::now);
  s.blend_s = 2.0;
  ASSERT_TRUE(q.add(s, 1.0, 20.0));
  double v = 0;
  ASSERT_TRUE(q.value_at(1.0, v));
  EXPECT_NEAR(v, 20.0, 1e-12);
  ASSERT_TRUE(q.value_at(2.0, v));
  EXPECT_NEAR(v, 60.0, 1e-12);
  ASSERT_TRUE(q.value_at(3.0, v));
  EXPECT_NEAR(v, 100.0, 1e-12);
}

TEST(SetpointSchedule, ParametricSegmentsEvaluateInClosedForm) {
  SetpointSegment sine;
  sine.kind = Kind::multisine;
  sine.timing = Timing::at;
  sine.start_s = 1.0;
  sine.count = 7;
  const double v[] = {96, 5, 0.1, 0.0, 12, 1.0, 0.5};
  std::copy(std::begin(v), std::end(v), sine.values.begin());
  const double t = 1.37;
  const double expect = 96 + 5 * std::sin(2 * std::numbers::pi * 0.1 * 0.37) + 12 * std::sin(2 * std::numbers::pi * 0.37 + 0.5);
  EXPECT_NEAR(segment_value(sine, t), expect, 1e-12);
  SetpointSegment ramp;
  ramp.kind = Kind::ramp;
  ramp.start_s = 0.0;
  ramp.values = {};
  ramp.values[0] = 10;
  ramp.values[1] = 30;
  ramp.values[2] = 4.0;
  EXPECT_NEAR(segment_value(ramp, 1.0), 15.0, 1e-12);
  EXPECT_NEAR(segment_value(ramp, 9.0), 30.0, 1e-12);
}

TEST(SetpointSchedule, FullQueueRefusesWithoutLosingWhatIsQueued) {
  SetpointSchedule q;
  for (int i = 0; i < SetpointSchedule::kCapacity; ++i) ASSERT_TRUE(q.add(hold(i, Timing::append, 0.0, 0.01), 0.0, 0.0));
  EXPECT_FALSE(q.add(hold(-1, Timing::append, 0.0, 0.01), 0.0, 0.0));
  EXPECT_EQ(q.size(), SetpointSchedule::kCapacity);
  double v = 0;
  ASSERT_TRUE(q.value_at(0.005, v));
  EXPECT_EQ(v, 0.0);
}
