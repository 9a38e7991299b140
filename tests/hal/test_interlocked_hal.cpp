// Interlock LOGIC behind the GpioLines interface. FakeGpioLines stands in for the
// kernel's GPIO lines, which this machine does not have; the libgpiod path itself
// is exercised by test_gpio_sim where gpio-sim exists (skipped otherwise).
// The wrapped backend is the real sim backend.
#include <gtest/gtest.h>

#include <limits>
#include <vector>

#include "control/controller.hpp"
#include "daemon/control_loop.hpp"
#include "hal/interlocked_hal.hpp"
#include "hal/sim_backend.hpp"

using namespace pvcgel;
using hal::HalStatus;

namespace {

/// Fake lines for logic tests only: records every drive of the enable output
/// and lets the test raise edges and levels.
struct FakeGpioLines final : hal::GpioLines {
  struct Shared {
    std::vector<bool> enable_writes;  // every set_enable() in order
    bool estop = false, amp_fault = false, pending_edge = false, read_fails = false, write_fails = false;
    int polls = 0;
  };
  explicit FakeGpioLines(Shared& s) : s_(s) {}
  bool set_enable(bool on) noexcept override {
    if (s_.write_fails && on) return false;
    s_.enable_writes.push_back(on);
    return true;
  }
  hal::InterlockInputs poll() noexcept override {
    ++s_.polls;
    hal::InterlockInputs in{s_.estop, s_.amp_fault, s_.pending_edge, !s_.read_fails};
    s_.pending_edge = false;
    return in;
  }
  Shared& s_;
};

/// A backend that records the order of calls relative to the lines.
struct OrderProbe final : hal::Hal {
  OrderProbe(std::vector<std::string>& log, FakeGpioLines::Shared& lines) : log_(log), lines_(lines) {}
  HalStatus read_displacement(double& y) noexcept override {
    y = 10.0 + 0.01 * static_cast<double>(++n_ % 7);
    return next_read;
  }
  HalStatus write_voltage(double v) noexcept override {
    log_.push_back("write " + std::to_string(static_cast<int>(v)) + " line " +
                   (lines_.enable_writes.empty() ? "-" : lines_.enable_writes.back() ? "on" : "off"));
    return HalStatus::ok;
  }
  HalStatus set_high_voltage(bool on) noexcept override {
    log_.push_back(std::string("hv ") + (on ? "on" : "off"));
    return HalStatus::ok;
  }
  [[nodiscard]] hal::HalHealth health() const noexcept override { return {}; }
  [[nodiscard]] std::string_view name() const noexcept override { return "probe"; }
  HalStatus next_read = HalStatus::ok;
  std::vector<std::string>& log_;
  FakeGpioLines::Shared& lines_;
  int n_ = 0;
};

struct Rig {
  FakeGpioLines::Shared lines;
  std::vector<std::string> log;
  OrderProbe* probe = nullptr;
  std::unique_ptr<hal::InterlockedHal> hal;
  explicit Rig(int trip_after_timeouts = 3) {
    auto p = std::make_unique<OrderProbe>(log, lines);
    probe = p.get();
    hal = std::make_unique<hal::InterlockedHal>(std::move(p), std::make_unique<FakeGpioLines>(lines), trip_after_timeouts);
  }
};

}  // namespace

TEST(InterlockLogic, EnableLineStartsInactiveAndFollowsTheLoop) {
  Rig r;
  ASSERT_EQ(r.lines.enable_writes, std::vector<bool>{false});
  EXPECT_EQ(r.hal->name(), "probe+gpio");
  EXPECT_EQ(r.hal->set_high_voltage(true), HalStatus::ok);
  EXPECT_EQ(r.lines.enable_writes.back(), true);
  EXPECT_EQ(r.log.back(), "hv on") << "the backend is enabled (at 0 V) before the line";
  EXPECT_TRUE(r.hal->health().high_voltage_enabled);
  EXPECT_EQ(r.hal->set_high_voltage(false), HalStatus::ok);
  EXPECT_EQ(r.lines.enable_writes.back(), false);
  EXPECT_FALSE(r.hal->health().high_voltage_enabled);
}

TEST(InterlockLogic, EstopEdgeDeassertsFirstAndIsADeviceFaultInTheSameCycle) {
  Rig r;
  ASSERT_EQ(r.hal->set_high_voltage(true), HalStatus::ok);
  double y = 0;
  ASSERT_EQ(r.hal->read_displacement(y), HalStatus::ok);
  ASSERT_EQ(r.hal->write_voltage(200.0), HalStatus::ok);
  // A short press: edge seen, level already back to released when polled.
  r.lines.pending_edge = true;
  EXPECT_EQ(r.hal->read_displacement(y), HalStatus::ok) << "the sensor reading itself is fine";
  EXPECT_EQ(r.lines.enable_writes.back(), false) << "deasserted at the poll, before anything else";
  EXPECT_EQ(r.hal->write_voltage(200.0), HalStatus::device_fault);
  EXPECT_EQ(r.log.back(), "write 200 line off") << "the backend's write happened with the line already off";
  EXPECT_TRUE(r.hal->tripped());
  EXPECT_TRUE(r.hal->health().amplifier_fault);
  // Latched until the loop disables and re-enables.
  EXPECT_EQ(r.hal->read_displacement(y), HalStatus::ok);
  EXPECT_EQ(r.hal->write_voltage(100.0), HalStatus::device_fault);
  r.hal->set_high_voltage(false);
  EXPECT_EQ(r.hal->set_high_voltage(true), HalStatus::ok);
  EXPECT_FALSE(r.hal->tripped());
  EXPECT_EQ(r.hal->write_voltage(100.0), HalStatus::ok);
}

TEST(InterlockLogic, ActiveInputRefusesToEnable) {
  Rig r;
  r.lines.amp_fault = true;
  EXPECT_EQ(r.hal->set_high_voltage(true), HalStatus::device_fault);
  for (bool w : r.lines.enable_writes) EXPECT_FALSE(w) << "never asserted while the amplifier reports a fault";
  r.lines.amp_fault = false;
  r.lines.estop = true;
  EXPECT_EQ(r.hal->set_high_voltage(true), HalStatus::device_fault);
  r.lines.estop = false;
  EXPECT_EQ(r.hal->set_high_voltage(true), HalStatus::ok);
  EXPECT_TRUE(r.lines.enable_writes.back());
}

TEST(InterlockLogic, UnreadableInputsAndFailingEnableCountAsFaults) {
  Rig r;
  r.lines.write_fails = true;
  EXPECT_EQ(r.hal->set_high_voltage(true), HalStatus::device_fault);
  r.lines.write_fails = false;
  ASSERT_EQ(r.hal->set_high_voltage(true), HalStatus::ok);
  r.lines.read_fails = true;
  double y = 0;
  r.hal->read_displacement(y);
  EXPECT_FALSE(r.lines.enable_writes.back());
  EXPECT_EQ(r.hal->write_voltage(0.0), HalStatus::device_fault);
}

TEST(InterlockLogic, BackendLinkFaultsDropTheLineAtOnce) {
  for (const auto bad : {HalStatus::disconnected, HalStatus::invalid_reply, HalStatus::device_fault}) {
    Rig r;
    ASSERT_EQ(r.hal->set_high_voltage(true), HalStatus::ok);
    r.probe->next_read = bad;
    double y = 0;
    EXPECT_EQ(r.hal->read_displacement(y), bad) << "the backend's status is passed on";
    EXPECT_FALSE(r.lines.enable_writes.back()) << to_string(bad);
  }
}

TEST(InterlockLogic, TimeoutsDropTheLineOnlyAfterTheConfiguredCount) {
  Rig r(3);
  ASSERT_EQ(r.hal->set_high_voltage(true), HalStatus::ok);
  r.probe->next_read = HalStatus::timeout;
  double y = 0;
  r.hal->read_displacement(y);
  r.hal->read_displacement(y);
  EXPECT_TRUE(r.lines.enable_writes.back()) << "two missed samples are tolerated";
  r.probe->next_read = HalStatus::ok;
  r.hal->read_displacement(y);
  r.probe->next_read = HalStatus::timeout;
  r.hal->read_displacement(y);
  r.hal->read_displacement(y);
  EXPECT_TRUE(r.lines.enable_writes.back()) << "the count restarts after a good reading";
  r.hal->read_displacement(y);
  EXPECT_FALSE(r.lines.enable_writes.back());
}

TEST(InterlockLogic, TheControlLoopFaultsWithinOneCycleOfAnEdgeAndTheLineIsOffBeforeTheRamp) {
  FakeGpioLines::Shared lines;
  control::ControllerConfig cc;
  control::Controller controller(control::paper_model(2), cc);
  hal::InterlockedHal ihal(std::make_unique<hal::SimBackend>(control::SimRigConfig{}),
                           std::make_unique<FakeGpioLines>(lines), 3);
  const auto trajectory = daemon::Trajectory::parse("hold:50");
  daemon::SafetyConfig safety;
  safety.soft_start_s = 0.2;
  daemon::ControlLoop loop(ihal, controller, trajectory, safety, 1e-3, std::numeric_limits<double>::infinity());
  for (int k = 0; k < 1000; ++k) loop.cycle(0.0f, 0);
  ASSERT_EQ(loop.state(), daemon::LoopState::running);
  ASSERT_TRUE(lines.enable_writes.back());
  lines.pending_edge = true;
  const auto rec = loop.cycle(0.0f, 0);
  EXPECT_EQ(rec.state, daemon::LoopState::ramp_down) << "within the cycle the edge was polled in";
  EXPECT_EQ(rec.fault, daemon::FaultReason::amplifier_fault);
  EXPECT_FALSE(lines.enable_writes.back()) << "HV enable dropped before the ramp, not after it";
  for (int k = 0; k < 3000 && loop.state() != daemon::LoopState::fault; ++k) loop.cycle(0.0f, 0);
  EXPECT_EQ(loop.state(), daemon::LoopState::fault);
  // Reset with the e-stop still pressed: DISABLED, never re-armed by itself, enable stays off.
  lines.estop = true;
  loop.request_reset();
  for (int k = 0; k < 50; ++k) loop.cycle(0.0f, 0);
  for (bool w : std::vector<bool>(lines.enable_writes.end() - 3, lines.enable_writes.end())) EXPECT_FALSE(w);
  EXPECT_EQ(loop.state(), daemon::LoopState::disabled);
}
