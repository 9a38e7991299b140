// pvcgeld: the real-time controller daemon for a PVC gel actuator rig.
#include <CLI/CLI.hpp>
#include <systemd/sd-daemon.h>

#include <cmath>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <optional>
#include <thread>

#include "control/config_error.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/dds_bridge.hpp"
#include "daemon/hal_factory.hpp"
#include "daemon/record_consumer.hpp"
#include "daemon/recorder.hpp"
#include "daemon/supervisor.hpp"

using namespace pvcgel;
using namespace pvcgel::daemon;

namespace {

constexpr int kExitOk = 0, kExitError = 1, kExitConfig = 2, kExitFault = 3;
constexpr int kExitUsage = 64;  ///< the command line itself is wrong (sysexits EX_USAGE), as pvcgel's

std::string iso_time_now() {
  char buf[32];
  const std::time_t t = std::time(nullptr);
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

struct Options {
  std::string config = "/etc/pvcgel/pvcgeld.toml";
  std::string trajectory, record, inject;
  double duration = NAN;
  bool check_only = false;
};

/// Everything the run needs, checked before anything starts.
struct Setup {
  DaemonConfig cfg;
  bool has_trajectory = false;
  Trajectory trajectory;
  std::optional<FaultInjection> inject;
};

Setup load_setup(const Options& opt) {
  Setup s{load_daemon_config(opt.config), false, Trajectory::parse("hold:0"), std::nullopt};
  if (!opt.trajectory.empty()) s.cfg.trajectory = opt.trajectory;
  if (!std::isnan(opt.duration)) s.cfg.duration_s = opt.duration;
  s.has_trajectory = !s.cfg.trajectory.empty();
  if (s.has_trajectory) {
    s.trajectory = Trajectory::parse(s.cfg.trajectory);
    // A local trajectory passes the same [setpoints] checks as one received over DDS (and the envelope at play time).
    s.trajectory.check_limits(s.cfg.setpoint_limits);
  }
  if (!opt.inject.empty()) s.inject = parse_fault_injection(opt.inject);
  return s;
}

std::unique_ptr<Recorder> open_recorder(const Options& opt, const DaemonConfig& cfg, const hal::Hal& hal) {
  if (opt.record.empty()) return nullptr;
  auto recorder = std::make_unique<Recorder>(
      opt.record, RecordingHeader{{"rate_hz", std::to_string(std::lround(1.0 / cfg.realtime.period_s))},
                                  {"config", opt.config},
                                  {"config_hash", cfg.config_hash},
                                  {"start_time", iso_time_now()},
                                  {"hal_backend", std::string(hal.name())},
                                  {"trajectory", cfg.trajectory},
                                  {"mode", std::string(control::to_string(cfg.rig.controller.mode))},
                                  {"soft_start_s", std::to_string(cfg.safety.soft_start_s)}});
  if (!recorder->created_directory().empty())
    std::fprintf(stderr, "pvcgeld: created directory %s for the recording\n", recorder->created_directory().c_str());
  return recorder;
}

void log_start(const Setup& s, const RealtimeReport& report, const hal::Hal& hal, bool dds) {
  const auto& cfg = s.cfg;
  if (!report.warnings.empty()) std::cerr << "pvcgeld: WARNING: " << report.warnings << "\n";
  std::cerr << "pvcgeld: loop running at " << 1.0 / cfg.realtime.period_s << " Hz, "
            << (report.realtime_scheduling ? "SCHED_FIFO priority " + std::to_string(cfg.realtime.priority)
                                           : std::string("NOT real-time (SCHED_OTHER)"))
            << ", memory " << (report.memory_locked ? "locked" : "NOT locked") << ", backend " << hal.name()
            << ", mode " << control::to_string(cfg.rig.controller.mode)
            << (s.has_trajectory ? ", trajectory " + cfg.trajectory : std::string(", idle (no trajectory)"))
            << (dds ? ", DDS as rig '" + cfg.dds.rig_id + "' on domain " + std::to_string(cfg.dds.domain) : std::string())
            << "\n";
}

void log_stop(const ControlLoop& loop, const LoopStatistics& s, const Recorder* recorder, const std::string& record_path,
              const hal::Hal& hal) {
  std::fprintf(stderr,
               "pvcgeld: stopped in state %s (fault: %s) after %llu cycles; wake-up latency p50 %.0f us, p99 %.0f "
               "us, p99.9 %.0f us, max %.0f us; compute p99 %.0f us; overruns %llu; records dropped %llu",
               to_string(loop.state()).data(), to_string(loop.fault()).data(),
               static_cast<unsigned long long>(s.cycles.load()), s.wakeup_latency.quantile_us(0.5),
               s.wakeup_latency.quantile_us(0.99), s.wakeup_latency.quantile_us(0.999),
               static_cast<double>(s.wakeup_latency.max_ns()) * 1e-3, s.compute_time.quantile_us(0.99),
               static_cast<unsigned long long>(s.overruns.load()),
               static_cast<unsigned long long>(s.records_dropped.load()));
  if (recorder)
    std::fprintf(stderr, "; recorded %llu rows to %s (sequence gaps %llu)", static_cast<unsigned long long>(recorder->rows()),
                 record_path.c_str(), static_cast<unsigned long long>(recorder->gaps()));
  std::fprintf(stderr, "; actuator failures %llu, envelope acted on reference %llu / output %llu cycles",
               static_cast<unsigned long long>(loop.actuator_failures()),
               static_cast<unsigned long long>(loop.envelope().reference_limited_cycles()),
               static_cast<unsigned long long>(loop.envelope().output().limited_cycles()));
  std::fprintf(stderr, "; hal %s: %s\n", hal.name().data(), health_summary(hal.health()).c_str());
}

/// Starts DDS, the loop thread and the record consumer, supervises until the loop is done, and logs the summary.
/// @return true when a signal asked the daemon to stop.
bool run_threads(const Options& opt, const Setup& setup, ControlLoop& loop, hal::Hal& hal, LoopIo& io,
                 Recorder* recorder) {
  const DaemonConfig& cfg = setup.cfg;
  const sigset_t signals = block_supervised_signals();  // before any thread starts: none of them sees a signal
  RealtimeReport report = prepare_process(cfg.realtime);
  auto stats = std::make_unique<LoopStatistics>();
  auto ring = std::make_unique<RecordRing>();
  auto latest = std::make_unique<LatestRecord>();
  std::atomic<bool> started{false}, loop_done{false};
  // DDS before the loop thread: joining may fail (a configuration error) and nothing may be running then.
  std::unique_ptr<DdsBridge> bridge;
  if (cfg.dds_enabled)
    bridge = std::make_unique<DdsBridge>(cfg.dds, cfg.setpoint_limits, io, *stats,
                                         DaemonIdentity{cfg.config_hash, PVCGEL_VERSION, std::string(hal.name()),
                                                        cfg.realtime.period_s});
  std::thread rt([&] {
    run_realtime_loop(loop, cfg.realtime, *stats, *ring, *latest, report, started);
    loop_done.store(true, std::memory_order_release);
  });
  RecordConsumer consumer(*ring, loop_done, recorder, bridge ? &bridge->telemetry() : nullptr);
  while (!started.load(std::memory_order_acquire)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  log_start(setup, report, hal, bridge != nullptr);
  sd_notify(0, "READY=1");
  Supervisor supervisor(loop, hal, *stats, *latest, signals, setup.has_trajectory ? INFINITY : cfg.duration_s);
  const bool signalled = supervisor.run(loop_done);
  rt.join();
  consumer.join();
  log_stop(loop, *stats, recorder, opt.record, hal);
  return signalled;
}

int run(const Options& opt) {
  const Setup setup = load_setup(opt);
  const DaemonConfig& cfg = setup.cfg;
  control::Controller controller(cfg.rig.model, cfg.rig.controller);
  if (opt.check_only) {
    // The simulated rig checks its [sim] table when it is built; a real backend is not connected to.
    if (cfg.hal.backend == "sim") make_hal(cfg, setup.inject);
    std::cout << "pvcgeld: configuration " << opt.config << " is valid (hash " << cfg.config_hash << ")\n";
    return kExitOk;
  }
  const auto hal = make_hal(cfg, setup.inject);
  ControlLoop loop(*hal, controller, setup.trajectory, cfg.safety, cfg.realtime.period_s, cfg.duration_s);
  loop.set_auto_start(setup.has_trajectory);
  loop.set_exit_on_fault(std::isfinite(cfg.duration_s));
  loop.set_limits(cfg.setpoint_limits);
  auto io = std::make_unique<LoopIo>();
  if (cfg.dds_enabled) loop.attach_io(*io, cfg.setpoint_limits);
  const auto recorder = open_recorder(opt, cfg, *hal);
  const bool signalled = run_threads(opt, setup, loop, *hal, *io, recorder.get());
  // Asked to stop (SIGTERM/SIGINT) the daemon did what it was told: exit 0 even when it was waiting in FAULT
  // (the fault is logged above); a run that ends in FAULT by itself exits 3.
  return loop.state() == LoopState::fault && !signalled ? kExitFault : kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pvcgeld: real-time controller daemon for PVC gel actuator rigs"};
  Options opt;
  app.add_option("-c,--config", opt.config, "configuration file")->capture_default_str();
  app.add_option("-t,--trajectory", opt.trajectory,
                 "setpoints: hold:R | sine:OFFSET,AMP,FREQ | multisine:OFFSET,A1,F1,... | csv:FILE | "
                 "paper-0.1hz | paper-0.5hz | paper-1hz | paper-multi");
  app.add_option("-d,--duration", opt.duration,
                 "play the trajectory this long (s) after its soft start (safety.soft_start_s, not counted), then ramp "
                 "down and exit; without a trajectory: run this long")
      ->check(CLI::PositiveNumber);
  app.add_option("-r,--record", opt.record,
                 "record every cycle to this CSV file (missing parent directories are created, and said so)");
  app.add_option("--inject-fault", opt.inject, "sim backend only: KIND@SECONDS, e.g. sensor_nan@3");
  app.add_flag("--check-config", opt.check_only, "validate the configuration and exit");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help is an "error" with code 0; everything else is a usage error.
    return app.exit(e) == 0 ? kExitOk : kExitUsage;
  }
  try {
    return run(opt);
  } catch (const control::ConfigError& e) {
    std::cerr << "pvcgeld: configuration error: " << e.what() << "\n";
    return kExitConfig;
  } catch (const std::exception& e) {
    std::cerr << "pvcgeld: " << e.what() << "\n";
    return kExitError;
  }
}
