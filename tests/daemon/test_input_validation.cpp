#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "daemon/input_validation.hpp"

using namespace pvcgel::daemon;

namespace {

struct Fixture {
  SetpointLimits limits;
  LoopView loop{.now_s = 10.0, .period_s = 1e-3, .target = LoopTarget::displacement, .queued_until_s = -1e300, .queued_segments = 0};
  std::vector<double> values;
  TrajectoryMessage msg(std::uint8_t kind, std::vector<double> v) {
    values = std::move(v);
    TrajectoryMessage m;
    m.rig_id = "rig1";
    m.client_id = "test";
    m.chunk_seq = 1;
    m.kind = kind;
    m.period_s = 1e-3;
    m.values = values;
    return m;
  }
  Verdict check(const TrajectoryMessage& m) {
    std::vector<SetpointSegment> out;
    Verdict v = validate_trajectory(m, limits, loop, out);
    EXPECT_EQ(out.empty(), !v.ok()) << "segments only when accepted";
    return v;
  }
};

}  // namespace

TEST(InputValidation, AcceptsThePaperReferencesAndCutsLongChunksIntoContiguousPieces) {
  Fixture f;
  EXPECT_TRUE(f.check(f.msg(3, {100, 25, 1.0, 0.0})).ok());
  EXPECT_TRUE(f.check(f.msg(4, {96, 5, 0.1, 0, 7, 0.5, 0, 12, 1.0, 0})).ok());
  std::vector<double> ramp(1000);
  for (int i = 0; i < 1000; ++i) ramp[static_cast<size_t>(i)] = 50.0 + 0.01 * i;
  auto m = f.msg(0, ramp);
  std::vector<SetpointSegment> out;
  ASSERT_TRUE(validate_trajectory(m, f.limits, f.loop, out).ok());
  ASSERT_EQ(out.size(), 8u);  // 7 x 128 + 104
  EXPECT_EQ(out[7].count, 1000 - 7 * 128);
  EXPECT_EQ(out[1].timing, SetpointSegment::Timing::append);
  EXPECT_NEAR(out[0].end_s - out[0].start_s, 128e-3, 1e-12);
  EXPECT_EQ(out[1].values[0], ramp[128]);
}

TEST(InputValidation, EachRuleRejectsWithItsReasonAndNamesTheValue) {
  Fixture f;
  auto nan_msg = f.msg(1, {NAN});
  EXPECT_EQ(f.check(nan_msg).reason, RejectReason::not_finite);
  auto inf_time = f.msg(1, {50});
  inf_time.blend_s = INFINITY;
  EXPECT_EQ(f.check(inf_time).reason, RejectReason::not_finite);
  const auto range = f.check(f.msg(1, {400}));
  EXPECT_EQ(range.reason, RejectReason::out_of_range);
  EXPECT_NE(range.detail.find("400"), std::string::npos) << range.detail;
  EXPECT_EQ(f.check(f.msg(3, {100, 150, 1, 0})).reason, RejectReason::out_of_range) << "sine swings below 0 um";
  const auto step = f.check(f.msg(0, {50, 50, 60}));
  EXPECT_EQ(step.reason, RejectReason::step_too_large);
  EXPECT_NE(step.detail.find("values[2]"), std::string::npos) << step.detail;
  EXPECT_EQ(f.check(f.msg(0, {50, 51, 52})).reason, RejectReason::slope_too_large) << "1 um per ms = 1000 um/s";
  EXPECT_EQ(f.check(f.msg(3, {100, 25, 5.0, 0})).reason, RejectReason::slope_too_large) << "2 pi 5 Hz 25 um = 785 um/s";
  auto past = f.msg(1, {50});
  past.start_time_s = 9.0;
  EXPECT_EQ(f.check(past).reason, RejectReason::in_the_past);
  auto ahead = f.msg(1, {50});
  ahead.start_time_s = 30.0;
  EXPECT_EQ(f.check(ahead).reason, RejectReason::too_far_ahead);
  // Appending to a queue that already reaches max_lead_s ahead is back-pressure, not a bad chunk.
  auto append = f.msg(1, {50});
  append.timing = 1;
  f.loop.queued_until_s = f.loop.now_s + f.limits.max_lead_s + 0.5;
  EXPECT_EQ(f.check(append).reason, RejectReason::busy);
  EXPECT_EQ(to_string(RejectReason::busy), "busy");
  f.loop.queued_until_s = -1e300;
  f.limits.max_chunk_samples = 100;
  EXPECT_EQ(f.check(f.msg(0, std::vector<double>(101, 50.0))).reason, RejectReason::chunk_too_large);
  auto fast = f.msg(0, {50, 50});
  fast.period_s = 1e-4;
  EXPECT_EQ(f.check(fast).reason, RejectReason::bad_period);
  auto volts = f.msg(1, {300});
  volts.target = 1;
  EXPECT_EQ(f.check(volts).reason, RejectReason::target_mismatch);
  EXPECT_EQ(f.check(f.msg(9, {50})).reason, RejectReason::malformed);
  EXPECT_EQ(f.check(f.msg(3, {100, 25, 1})).reason, RejectReason::malformed) << "sine needs 4 values";
  auto ramp = f.msg(2, {50, 60});
  EXPECT_EQ(f.check(ramp).reason, RejectReason::bad_duration) << "a ramp needs a duration";
  auto anon = f.msg(1, {50});
  anon.client_id = "";
  EXPECT_EQ(f.check(anon).reason, RejectReason::malformed);
  f.loop.queued_segments = SetpointSchedule::kCapacity;
  EXPECT_EQ(f.check(f.msg(1, {50})).reason, RejectReason::queue_full);
}

TEST(InputValidation, VoltageModeUsesTheVoltageLimits) {
  Fixture f;
  f.loop.target = LoopTarget::voltage;
  auto m = f.msg(3, {450, 300, 10.0, 0});
  m.target = 1;
  EXPECT_TRUE(f.check(m).ok()) << "the identification grid's fastest point: 2 pi 10 Hz 300 V = 18.8 kV/s";
  auto over = f.msg(3, {800, 300, 1.0, 0});
  over.target = 1;
  EXPECT_EQ(f.check(over).reason, RejectReason::out_of_range) << "1100 V";
}

TEST(InputValidation, StartStepNeedsABlendSlowEnoughForTheSlopeLimit) {
  SetpointLimits l;
  SetpointSegment s;
  s.target = LoopTarget::displacement;
  EXPECT_TRUE(start_step_allowed(s, 50.0, 51.5, l));
  EXPECT_FALSE(start_step_allowed(s, 50.0, 150.0, l));
  s.blend_s = 0.2;  // pi 100 / 0.4 = 785 um/s > 500
  EXPECT_FALSE(start_step_allowed(s, 50.0, 150.0, l));
  s.blend_s = 1.0;  // 157 um/s
  EXPECT_TRUE(start_step_allowed(s, 50.0, 150.0, l));
}

TEST(InputValidation, CommandsAndRateLimiter) {
  EXPECT_TRUE(validate_command(1, 0, "c", 1).ok());
  EXPECT_EQ(validate_command(0, 0, "c", 1).reason, RejectReason::unknown_command);
  EXPECT_EQ(validate_command(8, 0, "c", 1).reason, RejectReason::unknown_command);
  EXPECT_EQ(validate_command(5, 4, "c", 1).reason, RejectReason::bad_argument);
  EXPECT_EQ(validate_command(6, 2, "c", 1).reason, RejectReason::bad_argument);
  EXPECT_EQ(validate_command(1, 0, "c", 0).reason, RejectReason::malformed);
  RateLimiter r(10.0, 0.5);  // 10/s, burst 5
  int allowed = 0;
  for (int i = 0; i < 100; ++i) allowed += r.allow(100.0 + i * 1e-4);
  EXPECT_EQ(allowed, 5);
  EXPECT_TRUE(r.allow(100.2));
}

// A huge time is named in a few characters (%.10g), not as 300 digits cut off by the message buffer.
TEST(InputValidation, AHugeStartTimeIsNamedShortly) {
  Fixture f;
  auto m = f.msg(1, {50.0});
  m.start_time_s = 1e300;
  const Verdict v = f.check(m);
  EXPECT_EQ(v.reason, RejectReason::too_far_ahead);
  EXPECT_EQ(v.detail, "start_time_s 1e+300 is more than 10 s after the loop time 10");
}

TEST(InputValidation, UnknownTargetKindAndTimingCodesAreMalformedNotCast) {
  Fixture f;
  auto m = f.msg(5, {50.0});
  EXPECT_EQ(f.check(m).detail, "kind 5 is not 0..4 (samples, hold, ramp, sine, multisine)");
  m = f.msg(1, {50.0});
  m.target = 2;
  EXPECT_EQ(f.check(m).reason, RejectReason::malformed);
  m.target = 0;
  m.timing = 9;
  EXPECT_EQ(f.check(m).reason, RejectReason::malformed);
  m.timing = 0;
  EXPECT_TRUE(f.check(m).ok());
}
