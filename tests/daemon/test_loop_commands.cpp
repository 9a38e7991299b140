// The loop's side of the DDS interface: commands and setpoint segments taken
// from the lock-free queue, applied at their timestamps, answered.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "daemon/control_loop.hpp"
#include "hal/sim_backend.hpp"

using namespace pvcgel;
using namespace pvcgel::daemon;

namespace {

struct Rig {
  control::Controller controller{control::paper_model(2), control::ControllerConfig{}};
  hal::SimBackend sim{control::SimRigConfig{}};
  Trajectory idle = Trajectory::parse("hold:0");
  SafetyConfig safety = [] {
    SafetyConfig s;
    s.soft_start_s = 0.5;
    return s;
  }();
  std::unique_ptr<LoopIo> io = std::make_unique<LoopIo>();
  std::unique_ptr<ControlLoop> loop;
  std::uint32_t ticket = 0;
  CycleRecord last;

  explicit Rig(StaleSetpointPolicy policy = StaleSetpointPolicy::hold) {
    safety.stale_setpoint = policy;
    loop = std::make_unique<ControlLoop>(sim, controller, idle, safety, 1e-3, std::numeric_limits<double>::infinity());
    loop->set_auto_start(false);
    loop->attach_io(*io, SetpointLimits{});
  }
  std::uint32_t command(CommandKind k, std::uint8_t arg = 0) {
    LoopInput in;
    in.command = k;
    in.argument = arg;
    in.ticket = ++ticket;
    EXPECT_TRUE(io->inputs.push(in));
    return ticket;
  }
  std::uint32_t segment(const SetpointSegment& s) {
    LoopInput in;
    in.type = LoopInput::Type::segment;
    in.segment = s;
    in.ticket = ++ticket;
    EXPECT_TRUE(io->inputs.push(in));
    return ticket;
  }
  void run(int cycles) {
    for (int i = 0; i < cycles; ++i) last = loop->cycle(1.0f, 0);
  }
  /// The loop's answer to `t` (runs one cycle if none yet).
  RejectReason outcome(std::uint32_t t) {
    for (int tries = 0; tries < 2; ++tries) {
      while (auto o = io->outcomes.pop())
        if (o->ticket == t) return o->reason;
      run(1);
    }
    ADD_FAILURE() << "no outcome for ticket " << t;
    return RejectReason::malformed;  // the test has failed already; a value no command here expects
  }
};

SetpointSegment hold_now(double level, double blend_s = 0.0, LoopTarget target = LoopTarget::displacement) {
  SetpointSegment s;
  s.kind = SetpointSegment::Kind::hold;
  s.target = target;
  s.timing = SetpointSegment::Timing::now;
  s.values[0] = level;
  s.count = 1;
  s.blend_s = blend_s;
  s.chunk_seq = 42;
  return s;
}

}  // namespace

TEST(LoopCommands, ArmStartStopResetFollowTheStateMachineAndIllegalOnesAreRefused) {
  Rig r;
  r.run(10);
  EXPECT_EQ(r.loop->state(), LoopState::disabled);
  EXPECT_EQ(r.outcome(r.command(CommandKind::start)), RejectReason::illegal_in_state) << "start needs ARMED";
  EXPECT_EQ(r.outcome(r.command(CommandKind::reset)), RejectReason::illegal_in_state) << "reset needs FAULT";
  EXPECT_EQ(r.outcome(r.command(CommandKind::arm)), RejectReason::accepted);
  r.run(5);
  EXPECT_EQ(r.loop->state(), LoopState::armed);
  EXPECT_TRUE(r.last.high_voltage);
  EXPECT_EQ(r.last.u_V, 0.0);
  EXPECT_EQ(r.outcome(r.command(CommandKind::start)), RejectReason::accepted);
  r.run(5);
  EXPECT_EQ(r.loop->state(), LoopState::running);
  EXPECT_EQ(r.outcome(r.command(CommandKind::set_target, 1)), RejectReason::illegal_in_state) << "not while RUNNING";
  EXPECT_EQ(r.outcome(r.segment(hold_now(40.0, 2.0))), RejectReason::accepted);
  r.run(4000);
  EXPECT_NEAR(r.last.r_um, 40.0, 1e-9);
  EXPECT_NEAR(r.last.y_um, 40.0, 1.0);
  EXPECT_EQ(r.last.chunk_seq, 42u);
  EXPECT_EQ(r.outcome(r.command(CommandKind::stop)), RejectReason::accepted);
  r.run(2000);
  EXPECT_EQ(r.loop->state(), LoopState::disabled) << "a remote stop leaves the daemon running, DISABLED";
  EXPECT_FALSE(r.loop->finished());
  EXPECT_EQ(r.last.u_V, 0.0);
  EXPECT_FALSE(r.last.high_voltage);
}

TEST(LoopCommands, ArmIsRefusedWhileTheFaultsCauseIsPresentAndNamesIt) {
  Rig r;
  r.command(CommandKind::arm);
  r.command(CommandKind::start);
  r.run(600);
  r.sim.inject(hal::SimFault::amplifier_fault);
  r.run(2000);
  ASSERT_EQ(r.loop->state(), LoopState::fault);
  EXPECT_EQ(r.outcome(r.command(CommandKind::reset)), RejectReason::accepted);
  r.run(5);
  EXPECT_EQ(r.loop->state(), LoopState::disabled) << "DDS reset: FAULT -> DISABLED";
  EXPECT_FALSE(r.sim.health().high_voltage_enabled);
  const auto t = r.command(CommandKind::arm);
  r.run(1);
  bool seen = false;
  while (auto o = r.io->outcomes.pop()) {
    if (o->ticket != t) continue;
    seen = true;
    EXPECT_EQ(o->reason, RejectReason::illegal_in_state);
    EXPECT_EQ(static_cast<FaultReason>(o->cause), FaultReason::amplifier_fault) << "the refusal names the cause";
  }
  EXPECT_TRUE(seen);
  r.run(100);
  EXPECT_EQ(r.loop->state(), LoopState::disabled);
  EXPECT_FALSE(r.last.high_voltage);
  r.sim.inject(hal::SimFault::none);
  r.run(2);
  EXPECT_EQ(r.outcome(r.command(CommandKind::arm)), RejectReason::accepted) << "cause gone: arming is allowed again";
}

TEST(LoopCommands, ABlendLongerThanOnePieceIsOneContinuousCurve) {
  // The case: a 2 s blend on a chunk of samples cut into 128-sample pieces.
  Rig r;
  r.command(CommandKind::arm);
  r.command(CommandKind::start);
  r.run(600);
  EXPECT_EQ(r.outcome(r.segment(hold_now(80.0, 1.0))), RejectReason::accepted);
  r.run(1500);
  ASSERT_NEAR(r.last.r_um, 80.0, 1e-9);
  for (int p = 0; p < 16; ++p) {  // 2048 samples of 100 um
    SetpointSegment s = hold_now(100.0, p == 0 ? 2.0 : 0.0);
    s.kind = SetpointSegment::Kind::samples;
    s.count = SetpointSegment::kMaxValues;
    s.period_s = 1e-3;
    for (int i = 0; i < s.count; ++i) s.values[static_cast<size_t>(i)] = 100.0;
    s.timing = p == 0 ? SetpointSegment::Timing::now : SetpointSegment::Timing::append;
    s.continues = p > 0;
    s.start_s = 0.0;
    s.end_s = s.count * s.period_s;
    LoopInput in;
    in.type = LoopInput::Type::segment;
    in.segment = s;
    in.ticket = r.ticket + 1;
    in.last_piece = p == 15;
    ASSERT_TRUE(r.io->inputs.push(in));
  }
  ++r.ticket;
  double r_prev = r.last.r_um, max_dr = 0.0;
  for (int k = 0; k < 2100; ++k) {
    r.run(1);
    max_dr = std::max(max_dr, std::abs(r.last.r_um - r_prev));
    r_prev = r.last.r_um;
  }
  // A raised cosine over 20 um in 2 s peaks at pi 20 / (2 * 2) = 15.7 um/s: 0.0157 um per cycle.
  EXPECT_LT(max_dr, 0.0160) << "no step at a piece boundary";
  EXPECT_NEAR(r.last.r_um, 100.0, 1e-6);
}

TEST(LoopCommands, SetpointsArePlayedAtTheirTimestampsWithPreview) {
  Rig r;
  r.command(CommandKind::arm);
  r.command(CommandKind::start);
  r.run(600);  // past the soft start
  SetpointSegment at = hold_now(30.0, 0.5);
  at.timing = SetpointSegment::Timing::at;
  at.start_s = r.last.t_s + 1.0;
  at.end_s = std::numeric_limits<double>::infinity();
  const double start_at = at.start_s;
  EXPECT_EQ(r.outcome(r.segment(at)), RejectReason::accepted);
  const double r_held = r.last.r_um;  // the run holds where it started until setpoints play
  while (r.last.t_s < start_at - 0.0015) r.run(1);
  EXPECT_EQ(r.last.r_um, r_held) << "nothing plays before its timestamp";
  EXPECT_EQ(r.last.chunk_seq, 0u);
  r.run(2);
  EXPECT_EQ(r.last.chunk_seq, 42u) << "the segment is in force from its start time";
  EXPECT_LT(std::abs(r.last.r_um - r_held), 0.01) << "and blends from the setpoint in force";
  r.run(600);
  EXPECT_NEAR(r.last.r_um, 30.0, 1e-9);
}

TEST(LoopCommands, AStepFromTheSetpointInForceIsRefusedUnlessBlended) {
  Rig r;
  r.command(CommandKind::arm);
  r.command(CommandKind::start);
  r.run(600);
  EXPECT_EQ(r.outcome(r.segment(hold_now(80.0))), RejectReason::step_too_large);
  EXPECT_EQ(r.outcome(r.segment(hold_now(80.0, 1.0))), RejectReason::accepted);
}

TEST(LoopCommands, OpenLoopVoltageSetpointsAreSlewLimitedAndClamped) {
  Rig r;
  EXPECT_EQ(r.outcome(r.command(CommandKind::set_target, 1)), RejectReason::accepted);
  EXPECT_EQ(r.loop->target(), LoopTarget::voltage);
  EXPECT_EQ(r.outcome(r.segment(hold_now(50.0))), RejectReason::target_mismatch);
  r.command(CommandKind::arm);
  r.command(CommandKind::start);
  r.run(10);
  SetpointSegment sine = hold_now(0.0, 0.5, LoopTarget::voltage);
  sine.kind = SetpointSegment::Kind::sine;
  sine.count = 4;
  sine.values[0] = 450;
  sine.values[1] = 300;
  sine.values[2] = 1.0;
  sine.values[3] = 0.0;
  EXPECT_EQ(r.outcome(r.segment(sine)), RejectReason::accepted);
  double max_du = 0, u_prev = r.last.u_V, u_max = 0;
  for (int k = 0; k < 3000; ++k) {
    r.run(1);
    max_du = std::max(max_du, std::abs(r.last.u_V - u_prev));
    u_prev = r.last.u_V;
    u_max = std::max(u_max, r.last.u_V);
  }
  EXPECT_LE(max_du, r.safety.open_loop_slew_V_per_s * 1e-3 + 1e-9);
  EXPECT_NEAR(u_max, 750.0, 1.0);
  EXPECT_NEAR(r.last.u_V, r.last.r_um, 1e-6) << "after the blend u follows the voltage setpoint";
}

TEST(LoopCommands, RunningDryFollowsTheStaleSetpointPolicy) {
  Rig hold;
  hold.command(CommandKind::arm);
  hold.command(CommandKind::start);
  hold.run(600);
  SetpointSegment brief = hold_now(hold.last.r_um + 1.0);
  brief.end_s = 0.2;
  hold.segment(brief);
  hold.run(1000);
  EXPECT_EQ(hold.loop->state(), LoopState::running) << "hold policy: keep the last setpoint";

  Rig strict(StaleSetpointPolicy::ramp_down);
  strict.command(CommandKind::arm);
  strict.command(CommandKind::start);
  strict.run(600);
  brief.values[0] = strict.last.r_um + 1.0;
  strict.segment(brief);
  strict.run(1000);
  EXPECT_EQ(strict.loop->fault(), FaultReason::setpoint_stale);
}

TEST(LoopCommands, ModeSwitchByCommandIsBumpless) {
  Rig r;
  r.command(CommandKind::arm);
  r.command(CommandKind::start);
  r.run(600);
  r.segment(hold_now(r.last.r_um + 1.0, 0.5));
  r.run(2900);
  // Sensor noise moves u from cycle to cycle already; the switch must not move it more.
  double noise_du = 0.0, u_prev = r.last.u_V;
  for (int k = 0; k < 100; ++k) {
    r.run(1);
    noise_du = std::max(noise_du, std::abs(r.last.u_V - u_prev));
    u_prev = r.last.u_V;
  }
  const auto t = r.command(CommandKind::set_mode, static_cast<std::uint8_t>(control::ControllerMode::pid));
  r.run(1);
  EXPECT_EQ(r.outcome(t), RejectReason::accepted);
  EXPECT_EQ(r.last.mode, control::ControllerMode::pid);
  EXPECT_LE(std::abs(r.last.u_V - u_prev), 2.0 * noise_du) << "noise alone moves u by up to " << noise_du << " V";
}

// The bridge refuses unknown arguments already; the loop itself never casts one into an enum either.
TEST(LoopCommands, AnUnknownModeOrTargetArgumentIsRefusedNotCast) {
  Rig r;
  r.run(2);
  EXPECT_EQ(r.outcome(r.command(CommandKind::set_mode, 7)), RejectReason::bad_argument);
  EXPECT_EQ(r.outcome(r.command(CommandKind::set_target, 2)), RejectReason::bad_argument);
  EXPECT_EQ(r.loop->target(), LoopTarget::displacement);
  EXPECT_EQ(r.outcome(r.command(CommandKind::set_mode, 0)), RejectReason::accepted);
  EXPECT_EQ(r.outcome(r.command(CommandKind::set_target, 1)), RejectReason::accepted);
  EXPECT_EQ(r.loop->target(), LoopTarget::voltage);
}
