#include "tools/ident_rig.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <thread>

#include "control/identification/excitation_plan.hpp"
#include "daemon/control_loop.hpp"
#include "daemon/dds/dds_messages.hpp"
#include "tools/text_output.hpp"

namespace pvcgel::tools {

namespace fs = std::filesystem;
using control::identification::ExcitationPlan;
using control::identification::SinePoint;
using control::identification::SineRecord;
using daemon::CommandKind;
using daemon::LoopState;

namespace {

LoopState rig_state(DdsClient& c) { return state_of(c.status()); }

void wait_for_state(DdsClient& c, LoopState want, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (rig_state(c) != want) {
    if (std::chrono::steady_clock::now() > end)
      throw std::runtime_error("rig '" + c.options().rig + "' did not reach " + std::string(daemon::to_string(want)) +
                               " within " + format("%g", timeout_s) + " s (now " +
                               std::string(daemon::to_string(rig_state(c))) + ")");
    c.take_telemetry(1 << 16);  // keep the reliable reader drained
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

/// Back to a safe rest: ramp to 0 V, DISABLED, displacement setpoints.
void leave_safe(DdsClient& c) {
  const auto s = rig_state(c);
  if (s == LoopState::armed || s == LoopState::running) c.command(CommandKind::stop);
  if (s != LoopState::fault) wait_for_state(c, LoopState::disabled, 10.0);
  if (dds::checked_from_wire<daemon::LoopTarget>(c.status().target, "Status.target") != daemon::LoopTarget::displacement)
    c.command(CommandKind::set_target, to_wire(daemon::LoopTarget::displacement), false);
}

/// The sine segment of one experiment, in voltage, replacing what is queued. `v` holds its values and must
/// outlive the message.
pvcgel_v1_Trajectory sine_trajectory(const SinePoint& p, std::vector<double>& v) {
  v = {p.bias_V, p.amplitude_V, p.frequency_Hz, 0.0};
  pvcgel_v1_Trajectory t{};
  t.target = to_wire(daemon::LoopTarget::voltage);
  t.kind = to_wire(daemon::SetpointSegment::Kind::sine);
  t.timing = 0;  // replace what is queued (the wire's 0), starting now
  t.start_time_s = -1;
  // The blend from the previous voltage ends well inside the settling time, which is not analysed.
  t.blend_s = std::min(1.0, 0.5 * p.settle_s);
  t.values._buffer = v.data();
  t.values._length = t.values._maximum = 4;
  return t;
}

/// Appends one telemetry sample of the experiment to `r`; throws when the rig left RUNNING or a cycle was lost.
void append_sample(SineRecord& r, const pvcgel_v1_Telemetry& s, double& t0, std::uint64_t& last_seq) {
  const auto state = dds::checked_from_wire<LoopState>(s.state, "Telemetry.state");
  if (state != LoopState::running) {
    const auto fault = dds::checked_from_wire<daemon::FaultReason>(s.fault, "Telemetry.fault");
    throw std::runtime_error("the rig left RUNNING (" + std::string(daemon::to_string(state)) +
                             (fault != daemon::FaultReason::none ? ", fault " + std::string(daemon::to_string(fault)) : "") +
                             ")");
  }
  if (std::isnan(t0)) t0 = s.t_s;
  else if (s.seq != last_seq + 1)
    throw std::runtime_error("telemetry lost " + std::to_string(s.seq - last_seq - 1) + " cycles (sequence gap)");
  last_seq = s.seq;
  r.t_s.push_back(s.t_s - t0);
  r.u_V.push_back(s.u_V);
  r.y_um.push_back(s.y_um);
}

/// Throws when the rig refused the segment published as `seq`.
void throw_if_refused(DdsClient& c, std::uint64_t seq) {
  for (const auto& reply : c.take_replies())
    if (reply.seq == seq && !reply.accepted)
      throw std::runtime_error(
          "the rig refused the sine: " +
          std::string(daemon::to_string(dds::checked_from_wire<daemon::RejectReason>(reply.reason, "CommandReply.reason"))) +
          ": " + reply.detail);
}

/// One sine experiment: the segment is sent, and the telemetry of the cycles it
/// drives is collected for the experiment's whole duration.
SineRecord run_point(DdsClient& c, const SinePoint& p, double Ts) {
  std::vector<double> values;
  pvcgel_v1_Trajectory t = sine_trajectory(p, values);
  c.take_telemetry(1 << 16);  // drop what came before
  const auto seq = c.publish_trajectory(t);
  SineRecord r;
  r.point = p;
  r.sample_time_s = Ts;
  const auto rows = static_cast<std::size_t>(std::ceil(p.duration_s() / Ts));
  std::uint64_t last_seq = 0;
  double t0 = NAN;
  auto last_progress = std::chrono::steady_clock::now();
  while (r.t_s.size() < rows) {
    bool any = false;
    for (const auto& s : c.take_telemetry(1 << 16)) {
      any = true;
      if (s.chunk_seq == seq && r.t_s.size() < rows) append_sample(r, s, t0, last_seq);
    }
    throw_if_refused(c, seq);
    if (!any) {
      if (std::chrono::steady_clock::now() - last_progress > std::chrono::seconds(5))
        throw std::runtime_error("no telemetry for 5 s (daemon gone?)");
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    } else {
      last_progress = std::chrono::steady_clock::now();
    }
  }
  return r;
}

std::string fmt_point(const SinePoint& p) {
  return format("A%03.0f_B%03.0f_f%07.4fHz", p.amplitude_V, p.bias_V, p.frequency_Hz);
}

/// Connects for lossless telemetry and refuses a rig in FAULT; returns the loop period (s).
double connect_for_ident(DdsClient& c, const ClientOptions& rig) {
  try {
    c.connect();
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(std::string(e.what()) +
                             " (identification records lossless telemetry: the daemon needs [dds] reliable_telemetry = true)");
  }
  if (rig_state(c) == LoopState::fault)
    throw std::runtime_error("rig '" + rig.rig + "' is in FAULT (" + std::string(daemon::to_string(fault_of(c.status()))) +
                             "): clear it with `pvcgel reset` first");
  return c.status().period_s;
}

/// The held-out sines: the validation amplitude and bias at each validation frequency, 10 s or the
/// plan's fewest periods, whichever is longer (their voltages checked like the plan's).
std::vector<SinePoint> validation_points(const IdentArgs& a, double Ts) {
  std::vector<SinePoint> validation;
  for (double f : a.validation_frequencies_Hz)
    validation.push_back({a.validation_amplitude_V, a.validation_bias_V, f, a.grid.settle_s,
                          std::max(ExcitationPlan::kMinPeriods, static_cast<int>(std::ceil(10.0 * f)))});
  (void)ExcitationPlan(validation, Ts);  // checks the voltage range
  return validation;
}

/// Runs one sine experiment and writes its recording into `into` (named by the point).
SineRecord record_point(DdsClient& c, const SinePoint& p, double Ts, const ClientOptions& rig, const fs::path& into) {
  SineRecord r;
  try {
    r = run_point(c, p, Ts);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error("experiment " + fmt_point(p) + ": " + e.what());
  }
  write_sine_recording(into / (fmt_point(p) + ".csv"), r,
                       {{"rate_hz", format("%.0f", 1.0 / Ts)}, {"hal_backend", c.status().hal_backend}, {"rig_id", rig.rig},
                        {"trajectory", format("ident-sine:%g,%g,%g", p.bias_V, p.amplitude_V, p.frequency_Hz)},
                        {"mode", "open_loop"}, {"settle_s", format("%g", p.settle_s)}});
  return r;
}

}  // namespace

std::string run_plan_on_rig(const IdentArgs& a, const ClientOptions& rig, const fs::path& dir) {
  DdsClient c(rig, true, true);
  const double Ts = connect_for_ident(c, rig);
  const auto plan = ExcitationPlan::from_grid(a.grid, Ts);
  const std::vector<SinePoint> validation = validation_points(a, Ts);
  double total_s = 0;
  for (const auto& p : plan.points()) total_s += p.duration_s();
  for (const auto& p : validation) total_s += p.duration_s();
  std::fprintf(stderr, "pvcgel ident: %zu + %zu sine experiments on rig '%s', about %.0f s\n", plan.points().size(),
               validation.size(), rig.rig.c_str(), total_s);
  leave_safe(c);
  c.command(CommandKind::set_target, to_wire(daemon::LoopTarget::voltage));
  try {
    c.command(CommandKind::arm);
    c.command(CommandKind::start);
    wait_for_state(c, LoopState::running, 5.0);
    std::size_t i = 0;
    const std::size_t n = plan.points().size() + validation.size();
    for (const auto& [points, into] : {std::pair{&plan.points(), dir}, std::pair{&validation, dir / "validation"}})
      for (const auto& p : *points) {
        const SineRecord r = record_point(c, p, Ts, rig, into);
        std::fprintf(stderr, "[%zu/%zu] A = %.0f V, B = %.0f V, f = %.3f Hz: %.1f s recorded\n", ++i, n, p.amplitude_V,
                     p.bias_V, p.frequency_Hz, static_cast<double>(r.t_s.size()) * Ts);
      }
  } catch (...) {
    leave_safe(c);  // 0 V and high voltage off before anything else is reported
    throw;
  }
  leave_safe(c);
  return "Rig: '" + rig.rig + "' over DDS (domain " + std::to_string(rig.domain) + "), " +
         std::to_string(plan.points().size()) + " experiments + " + std::to_string(validation.size()) +
         " held out, recordings in " + dir.string() + "\n";
}

}  // namespace pvcgel::tools
