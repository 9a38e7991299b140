// Proof that the real-time path does not allocate: this executable replaces the global
// allocation functions with counting versions, so it is built on its own (see
// tests/CMakeLists.txt) and must not be linked into test_control.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <cstdlib>
#include <new>
#include <ostream>
#include <span>
#include <vector>

#include "control/controller.hpp"
#include "support/allocation_counter.hpp"
#include "control/reference_signal.hpp"
#include "control/simulated_rig.hpp"

namespace pvcgel::control {

// Readable test parameters in gtest / ctest output (found by ADL).
void PrintTo(ControllerMode m, std::ostream* os) { *os << to_string(m); }

namespace {

// Keeps the optimiser from eliding an allocation whose result is otherwise unused.
template <class T>
void escape(T* p) {
  asm volatile("" : : "g"(p) : "memory");
}

TEST(NoAllocation, CounterSeesAllocations) {
  const long before = g_allocations.load();
  std::vector<double> v;
  v.push_back(1.0);
  escape(v.data());
  EXPECT_GE(g_allocations.load() - before, 1) << "the counting operator new is not in effect";
  auto* p = new int(3);
  escape(p);
  delete p;
  EXPECT_GE(g_allocations.load() - before, 2);
}

class NoAllocation : public ::testing::TestWithParam<ControllerMode> {};

TEST_P(NoAllocation, ControllerStepRigAndModeSwitchesDoNotAllocate) {
  const auto model = paper_model(2);
  ControllerConfig cfg;
  cfg.mode = GetParam();
  Controller ctl(model, cfg);  // design time: may allocate
  SimulatedRig rig(SimRigConfig{});
  const auto ref = *paper_reference("multi");
  const double Ts = cfg.sample_time_s;
  std::array<double, 8> window{};
  const int len = ctl.preview_samples() + 1;
  ASSERT_LE(len, static_cast<int>(window.size()));
  for (int i = 0; i < len; ++i) window[static_cast<size_t>(i)] = ref(i * Ts);
  ctl.reset_steady_state(window[0]);
  rig.reset_steady_state(ctl.last_voltage_V());

  double checksum = 0.0;
  long bad = 0;
  const long before = g_allocations.load();
  for (long k = 0; k < 10000; ++k) {
    if (k % 997 == 500) ctl.set_mode(kAllModes[static_cast<size_t>((k / 997 + 1) % 4)]);
    const double y = rig.measure();
    const auto out = ctl.step(std::span<const double>(window.data(), static_cast<size_t>(len)), y);
    rig.apply(out.voltage_V);
    checksum += out.voltage_V + rig.true_displacement_um();
    if (!std::isfinite(out.voltage_V) || out.status == ControlOutput::Status::invalid_input) ++bad;
    for (int i = 0; i + 1 < len; ++i) window[static_cast<size_t>(i)] = window[static_cast<size_t>(i + 1)];
    window[static_cast<size_t>(len - 1)] = ref(static_cast<double>(k + len) * Ts);
    if (k == 5000) ctl.reset_steady_state(window[0]);  // noexcept, also on the RT path
  }
  const long after = g_allocations.load();
  EXPECT_EQ(after - before, 0) << "allocations on the real-time path";
  EXPECT_EQ(bad, 0);
  EXPECT_TRUE(std::isfinite(checksum));
}

TEST(NoAllocation, SimulatedRigRunningADiagnosedEffectDoesNotAllocate) {
  // Every effect `pvcgel diagnose` can write into [[sim.truth.effect]], alone and in mixtures of two
  // (every effect paired with its neighbour in this list, log-type creep and a partial mode included).
  const std::vector<Effect> effects{
      {EffectKind::hysteresis, {0.02, 20.0, 1.5}}, {EffectKind::creep, {0.01, 3.0, 1.5}},
      {EffectKind::dead_zone, {20.0, 30.0}},   {EffectKind::saturation, {100.0, 500.0}},
      {EffectKind::delay, {2.5e-3}},           {EffectKind::asymmetric_dynamics, {0.3}},
      {EffectKind::slew_limit, {2000.0}},      {EffectKind::resonance, {20.0, 0.1, 0.95}},
      {EffectKind::drift, {0.1, 0.01, 1.0}},   {EffectKind::bias_dependent_dynamics, {0.3, 0.5}},
      {EffectKind::saturation, {100.0, 500.0, 1.0}}};  // on the drive
  std::vector<std::vector<Effect>> runs;
  for (size_t i = 0; i < effects.size(); ++i) {
    runs.push_back({effects[i]});
    runs.push_back({effects[i], effects[(i + 1) % effects.size()]});
  }
  for (const auto& mix : runs) {
    SimRigConfig c = SimRigConfig{}.exactly(paper_model(3));
    c.noise_sigma_um = 0.05;
    c.added_effects = mix;
    const auto& e = mix.back();
    SimulatedRig rig(c);  // design time: may allocate
    double checksum = 0.0;
    const long before = g_allocations.load();
    rig.reset_steady_state(300.0);
    for (long k = 0; k < 3000; ++k) {
      checksum += rig.measure();
      rig.apply(300.0 + 100.0 * std::sin(0.01 * static_cast<double>(k)));
    }
    EXPECT_EQ(g_allocations.load() - before, 0) << to_string(mix.front().kind) << " + " << to_string(e.kind);
    EXPECT_TRUE(std::isfinite(checksum));
  }
}

TEST(NoAllocation, ControllerCompensatingEachEffectAndMixturesDoesNotAllocate) {
  // Every effect the controller compensates ([[model.effect]]), alone and in mixtures of two,
  // in every mode (switches included), on a rig whose truth has the same effects.
  const std::vector<Effect> effects{{EffectKind::hysteresis, {0.1, 30.0, -0.5}}, {EffectKind::creep, {0.05, 10.0, 1.0}},
                                    {EffectKind::dead_zone, {20.0, 30.0}}, {EffectKind::saturation, {100.0, 50.0}},
                                    {EffectKind::delay, {2.5e-3}},         {EffectKind::slew_limit, {20000.0}},
                                    {EffectKind::drift, {0.1, 0.01, 1.0}}, {EffectKind::saturation, {100.0, 50.0, 1.0}}};
  std::vector<std::vector<Effect>> runs;
  for (size_t i = 0; i < effects.size(); ++i) {
    runs.push_back({effects[i]});
    runs.push_back({effects[i], effects[(i + 1) % effects.size()]});
  }
  const auto ref = *paper_reference("multi");
  for (const auto& mix : runs) {
    ControllerConfig cfg;
    cfg.effects = mix;
    Controller ctl(paper_model(2), cfg);  // design time: may allocate
    SimRigConfig rc = SimRigConfig{}.exactly(paper_model(2));
    rc.added_effects = mix;
    SimulatedRig rig(rc);
    std::array<double, 8> window{};
    const int len = ctl.preview_samples() + 1;
    ASSERT_LE(len, static_cast<int>(window.size()));
    double checksum = 0.0;
    const long before = g_allocations.load();
    ctl.reset_steady_state(ref(0.0));
    rig.reset_steady_state(ctl.last_voltage_V());
    for (long k = 0; k < 4000; ++k) {
      if (k % 997 == 500) ctl.set_mode(kAllModes[static_cast<size_t>((k / 997 + 1) % 4)]);
      for (int i = 0; i < len; ++i) window[static_cast<size_t>(i)] = ref(static_cast<double>(k + i) * 1e-3);
      const auto out = ctl.step(std::span<const double>(window.data(), static_cast<size_t>(len)), rig.measure());
      rig.apply(out.voltage_V);
      checksum += out.voltage_V;
    }
    EXPECT_EQ(g_allocations.load() - before, 0) << to_string(mix.front().kind) << " + " << to_string(mix.back().kind);
    EXPECT_TRUE(std::isfinite(checksum));
  }
}

INSTANTIATE_TEST_SUITE_P(AllModes, NoAllocation, ::testing::ValuesIn(kAllModes),
                         [](const auto& param_info) { return std::string(to_string(param_info.param)); });

}  // namespace
}  // namespace pvcgel::control
