// Property test of the safety envelope in accelerated simulation: the real
// ControlLoop, the sim backend and the DDS validator, driven cycle by cycle
// (no real time) for thousands of simulated seconds by one or two random
// "clients" sending trajectories (samples, holds, ramps, sines, with and
// without blends, replacing or appending), mode and target switches, arm,
// start, stop, clear and reset, while faults come and go. On every cycle:
// the played reference never exceeds the range, step or slope limits, and the
// voltage never exceeds its range or slew limit, except in the fault/stop ramp
// (down only, at its own rate); high voltage (as the HAL reports it) is off in
// DISABLED and FAULT.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "daemon/control_loop.hpp"
#include "hal/sim_backend.hpp"

using namespace pvcgel;
using namespace pvcgel::daemon;

namespace {

constexpr double kTs = 1e-3;

struct Client {
  std::string id;
  std::uint64_t seq = 0;
};

struct Harness {
  control::Controller controller{control::paper_model(2), [] {
                                   control::ControllerConfig c;
                                   c.slew_limit_V_per_s = 30000.0;  // as pvcgeld configures it
                                   return c;
                                 }()};
  hal::SimBackend sim{control::SimRigConfig{}};
  Trajectory idle = Trajectory::parse("hold:0");
  SafetyConfig safety = [] {
    SafetyConfig s;
    s.soft_start_s = 0.5;
    s.ramp_down_V_per_s = 2000.0;
    return s;
  }();
  SetpointLimits limits{};
  std::unique_ptr<LoopIo> io = std::make_unique<LoopIo>();
  std::unique_ptr<ControlLoop> loop;
  std::uint32_t ticket = 0;
  std::mt19937_64 rng;

  explicit Harness(std::uint64_t seed) : rng(seed) {
    loop = std::make_unique<ControlLoop>(sim, controller, idle, safety, kTs, std::numeric_limits<double>::infinity());
    loop->set_auto_start(false);
    loop->attach_io(*io, limits);
  }
  double uniform(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); }
  bool chance(double p) { return uniform(0.0, 1.0) < p; }

  void command(CommandKind k, std::uint8_t arg = 0) {
    LoopInput in;
    in.command = k;
    in.argument = arg;
    in.ticket = ++ticket;
    io->inputs.push(in);
  }
  /// A random trajectory message through the real validator; accepted pieces go to the loop.
  int trajectory(Client& c) {
    const LoopSnapshot snap = io->snapshot.read();
    const bool volts = snap.target == LoopTarget::voltage;
    const double lo = volts ? 0.0 : 5.0, hi = volts ? 900.0 : 250.0;
    std::vector<double> values;
    TrajectoryMessage m;
    m.client_id = c.id;
    m.chunk_seq = ++c.seq;
    m.target = volts ? 1 : 0;
    m.timing = chance(0.5) ? 1 : 0;
    m.blend_s = chance(0.6) ? uniform(0.05, 3.0) : 0.0;
    const int kind = static_cast<int>(uniform(0.0, 4.0));
    const double level = uniform(lo, hi);
    if (kind == 0) {  // samples: a constant far away (the blend case of the issue) or a slow walk
      const int n = static_cast<int>(uniform(50, 1024));
      double v = level;
      const double drift = chance(0.5) ? 0.0 : uniform(-0.3, 0.3) * (volts ? 10.0 : 1.0);
      for (int i = 0; i < n; ++i) values.push_back(v = std::clamp(v + drift, lo, hi));
      m.period_s = kTs;
    } else if (kind == 1) {
      values = {level};
      m.duration_s = chance(0.5) ? uniform(0.2, 5.0) : 0.0;
    } else if (kind == 2) {
      values = {uniform(lo, hi), level};
      m.duration_s = uniform(0.5, 5.0);
    } else {
      const double amp = uniform(0.0, volts ? 200.0 : 40.0);
      values = {std::clamp(level, lo + amp, hi - amp), amp, uniform(0.05, 2.0), 0.0};
      m.duration_s = chance(0.5) ? uniform(0.5, 8.0) : 0.0;
    }
    m.kind = static_cast<std::uint8_t>(kind == 3 ? 3 : kind);
    m.values = values;
    LoopView view{snap.now_s, kTs, snap.target, snap.queued_until_s, snap.queued_segments};
    std::vector<SetpointSegment> pieces;
    if (!validate_trajectory(m, limits, view, pieces).ok()) return 0;
    ++ticket;
    for (size_t i = 0; i < pieces.size(); ++i) {
      LoopInput in;
      in.type = LoopInput::Type::segment;
      in.segment = pieces[i];
      in.ticket = ticket;
      in.last_piece = i + 1 == pieces.size();
      if (!io->inputs.push(in)) return 0;
    }
    return 1;
  }
};

struct Tally {
  long running_displacement = 0, running_voltage = 0, ramp = 0, resets = 0, faults = 0, accepted_chunks = 0;
  long blends_accepted = 0, refused = 0;
};

void run_property(std::uint64_t seed, int clients, double simulated_s, Tally& tally) {
  Harness h(seed);
  std::vector<Client> cs;
  for (int i = 0; i < clients; ++i) cs.push_back({"client" + std::to_string(i)});
  const double r_step = std::min(h.limits.max_step_um, h.limits.max_slope_um_per_s * kTs) + 1e-9;
  const double rv_step =
      std::min(h.limits.max_step_V, std::min(h.limits.max_slope_V_per_s, h.safety.open_loop_slew_V_per_s) * kTs) + 1e-9;
  const double u_step = h.safety.output_slew_V_per_s * kTs + 1e-9;
  const double ramp_step = h.safety.ramp_down_V_per_s * kTs + 1e-9;
  const auto cycles = static_cast<long>(simulated_s / kTs);
  CycleRecord prev = h.loop->cycle(0.0f, 0);
  hal::SimFault active = hal::SimFault::none;
  for (long k = 1; k < cycles; ++k) {
    // Inputs, about every 20 ms of simulated time.
    if (h.chance(0.05)) {
      const auto state = h.io->snapshot.read().state;
      const double p = h.uniform(0.0, 1.0);
      if (p < 0.55) tally.accepted_chunks += h.trajectory(cs[static_cast<size_t>(h.uniform(0, clients))]);
      else if (p < 0.65) h.command(state == LoopState::disabled ? CommandKind::arm : CommandKind::start);
      else if (p < 0.68) h.command(CommandKind::stop);
      else if (p < 0.75) h.command(CommandKind::reset);
      else if (p < 0.80) h.command(CommandKind::set_mode, static_cast<std::uint8_t>(h.uniform(0, 4)));
      else if (p < 0.83) h.command(CommandKind::set_target, h.chance(0.7) ? 0 : 1);
      else if (p < 0.85) h.command(CommandKind::clear);
    }
    // Faults come and go (rarely, so most time is spent running).
    if (active == hal::SimFault::none && h.chance(2e-5)) {
      const hal::SimFault kinds[] = {hal::SimFault::amplifier_fault, hal::SimFault::sensor_nan, hal::SimFault::write_failed,
                                     hal::SimFault::sensor_dropout, hal::SimFault::hv_enable_failed};
      h.sim.inject(active = kinds[static_cast<size_t>(h.uniform(0, 5))]);
    } else if (active != hal::SimFault::none && h.chance(1e-3)) {
      h.sim.inject(active = hal::SimFault::none);
    }
    const CycleRecord rec = h.loop->cycle(0.0f, 0);
    while (auto o = h.io->outcomes.pop()) tally.refused += o->reason != RejectReason::accepted;

    // The invariant.
    ASSERT_GE(rec.u_V, h.controller.config().voltage_min_V) << "seed " << seed << " t " << rec.t_s;
    ASSERT_LE(rec.u_V, h.controller.config().voltage_max_V) << "seed " << seed << " t " << rec.t_s;
    // A cycle that starts in RAMP_DOWN is the ramp's (a fault found at the write starts it next cycle).
    const bool ramp = prev.state == LoopState::ramp_down;
    if (ramp) {
      ASSERT_LE(rec.u_V, prev.u_V + 1e-9) << "the ramp only goes down; t " << rec.t_s;
      ASSERT_LE(prev.u_V - rec.u_V, ramp_step) << "ramp rate; t " << rec.t_s;
      ++tally.ramp;
    } else {
      ASSERT_LE(std::abs(rec.u_V - prev.u_V), u_step) << "slew; seed " << seed << " t " << rec.t_s << " state "
                                                      << to_string(rec.state) << " after " << to_string(prev.state);
    }
    if (rec.state == LoopState::disabled || rec.state == LoopState::fault) {
      ASSERT_FALSE(rec.high_voltage) << "HV on in " << to_string(rec.state) << " at t " << rec.t_s;
    }
    if (rec.state == LoopState::running && prev.state == LoopState::running && rec.target == prev.target) {
      if (rec.target == LoopTarget::displacement) {
        ++tally.running_displacement;
        ASSERT_GE(rec.r_um, h.limits.min_um);
        ASSERT_LE(rec.r_um, h.limits.max_um);
        ASSERT_LE(std::abs(rec.r_um - prev.r_um), r_step) << "reference step; seed " << seed << " t " << rec.t_s;
      } else {
        ++tally.running_voltage;
        ASSERT_LE(std::abs(rec.r_um - prev.r_um), rv_step) << "voltage setpoint step; seed " << seed << " t " << rec.t_s;
      }
    }
    if (rec.state == LoopState::fault && prev.state != LoopState::fault) ++tally.faults;
    if (rec.state == LoopState::disabled && prev.state == LoopState::fault) ++tally.resets;
    prev = rec;
  }
}

TEST(SafetyEnvelopeProperty, RandomClientsNeverBreakTheEnvelope) {
  Tally tally;
  run_property(1, 1, 1500.0, tally);
  if (HasFatalFailure()) return;
  run_property(2, 2, 1500.0, tally);
  if (HasFatalFailure()) return;
  std::printf("3000 simulated s: %ld running cycles closed loop, %ld open loop, %ld ramp cycles, %ld faults, %ld resets, "
              "%ld chunks accepted by the validator, %ld inputs refused by the loop\n",
              tally.running_displacement, tally.running_voltage, tally.ramp, tally.faults, tally.resets,
              tally.accepted_chunks, tally.refused);
  // The run must have exercised what it claims to test.
  EXPECT_GT(tally.running_displacement, 300000);
  EXPECT_GT(tally.running_voltage, 10000);
  EXPECT_GT(tally.faults, 3);
  EXPECT_GT(tally.resets, 3);
  EXPECT_GT(tally.accepted_chunks, 1000);
}

}  // namespace
