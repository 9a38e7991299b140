// Proves the real-time cycle (HAL read, safety checks, controller, HAL write,
// record) never allocates: global operator new is replaced by a counting one.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <vector>

#include "daemon/control_loop.hpp"
#include "daemon/realtime_thread.hpp"
#include "hal/sim_backend.hpp"
#include "support/allocation_counter.hpp"

using namespace pvcgel;

TEST(LoopNoAllocation, CounterWorks) {
  const long before = g_allocations.load();
  std::vector<int> v;
  v.push_back(1);
  EXPECT_GT(g_allocations.load(), before) << "the counting operator new is not in effect";
}

TEST(LoopNoAllocation, CyclesOfEveryModeAndFaultPathAllocateNothing) {
  control::Controller controller(control::paper_model(2), control::ControllerConfig{});
  hal::SimBackend sim(control::SimRigConfig{});
  const auto trajectory = daemon::Trajectory::parse("paper-multi");
  daemon::ControlLoop loop(sim, controller, trajectory, daemon::SafetyConfig{}, 1e-3,
                           std::numeric_limits<double>::infinity());
  loop.set_exit_on_fault(true);
  auto ring = std::make_unique<daemon::RecordRing>();

  const long before = g_allocations.load();
  for (int k = 0; k < 12000; ++k) {
    if (k % 2500 == 0) controller.set_mode(control::kAllModes[static_cast<size_t>((k / 2500) % 4)]);
    if (k == 11000) sim.inject(hal::SimFault::sensor_nan);  // fault path and ramp-down too
    const auto rec = loop.cycle(1.0f, 0);
    if (!ring->push(rec)) (void)ring->pop();
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
  EXPECT_EQ(loop.fault(), daemon::FaultReason::sensor_nan);
}

TEST(LoopNoAllocation, CommandsAndReceivedSetpointsAllocateNothingInTheLoop) {
  control::Controller controller(control::paper_model(2), control::ControllerConfig{});
  hal::SimBackend sim(control::SimRigConfig{});
  const auto idle = daemon::Trajectory::parse("hold:0");
  auto io = std::make_unique<daemon::LoopIo>();
  daemon::ControlLoop loop(sim, controller, idle, daemon::SafetyConfig{}, 1e-3, std::numeric_limits<double>::infinity());
  loop.set_auto_start(false);
  loop.attach_io(*io, daemon::SetpointLimits{});
  daemon::LoopInput cmd;
  daemon::LoopInput seg;
  seg.type = daemon::LoopInput::Type::segment;
  seg.segment.kind = daemon::SetpointSegment::Kind::samples;
  seg.segment.timing = daemon::SetpointSegment::Timing::append;
  seg.segment.period_s = 1e-3;
  seg.segment.count = daemon::SetpointSegment::kMaxValues;
  seg.segment.end_s = seg.segment.count * 1e-3;

  const long before = g_allocations.load();
  std::uint32_t ticket = 0;
  for (int k = 0; k < 8000; ++k) {
    cmd.ticket = ++ticket;
    if (k == 10) cmd.command = daemon::CommandKind::arm, io->inputs.push(cmd);
    if (k == 20) cmd.command = daemon::CommandKind::start, io->inputs.push(cmd);
    if (k >= 100 && k % 100 == 0) {
      for (int i = 0; i < seg.segment.count; ++i)
        seg.segment.values[static_cast<size_t>(i)] = 20.0 + 5.0 * std::sin(2e-3 * (k + i));
      seg.ticket = ++ticket;
      io->inputs.push(seg);
    }
    if (k % 1000 == 500) cmd.command = daemon::CommandKind::set_mode, cmd.argument = static_cast<std::uint8_t>(k / 1000 % 4),
                         io->inputs.push(cmd);
    if (k == 7000) cmd.command = daemon::CommandKind::stop, io->inputs.push(cmd);
    (void)loop.cycle(1.0f, 0);
    while (io->outcomes.pop()) {
    }
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
  EXPECT_EQ(loop.state(), daemon::LoopState::disabled);
}

TEST(LoopNoAllocation, CyclesWithCompensatedEffectsAllocateNothing) {
  // A model file with [[model.effect]] (hysteresis and a delay) on a rig whose truth has them.
  control::ControllerConfig cfg;
  cfg.effects = {{control::EffectKind::hysteresis, {0.1, 40.0}}, {control::EffectKind::delay, {2.5e-3}}};
  control::Controller controller(control::paper_model(2), cfg);
  auto rig = control::SimRigConfig{}.exactly(control::paper_model(2));
  rig.added_effects = cfg.effects;
  hal::SimBackend sim(rig);
  const auto trajectory = daemon::Trajectory::parse("paper-multi");
  daemon::ControlLoop loop(sim, controller, trajectory, daemon::SafetyConfig{}, 1e-3,
                           std::numeric_limits<double>::infinity());
  auto ring = std::make_unique<daemon::RecordRing>();

  const long before = g_allocations.load();
  for (int k = 0; k < 10000; ++k) {
    if (k % 2500 == 0) controller.set_mode(control::kAllModes[static_cast<size_t>((k / 2500 + 3) % 4)]);
    const auto rec = loop.cycle(1.0f, 0);
    if (!ring->push(rec)) (void)ring->pop();
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
  EXPECT_EQ(loop.fault(), daemon::FaultReason::none);
}
