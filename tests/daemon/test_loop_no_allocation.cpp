// Proves the real-time cycle (HAL read, safety checks, controller, HAL write,
// record) never allocates: global operator new is replaced by a counting one.
#include <gtest/gtest.h>

#include <atomic>
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
