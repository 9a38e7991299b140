// pvcgeld: the real-time controller daemon for a PVC gel actuator rig.
#include <CLI/CLI.hpp>
#include <systemd/sd-daemon.h>

#include <charconv>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <thread>

#include "control/config_error.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/hal_factory.hpp"
#include "daemon/recorder.hpp"
#include "daemon/dds_bridge.hpp"
#include "hal/sim_backend.hpp"

using namespace pvcgel;
using namespace pvcgel::daemon;

namespace {

constexpr int kExitOk = 0, kExitError = 1, kExitConfig = 2, kExitFault = 3;

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

int run(const Options& opt) {
  DaemonConfig cfg = load_daemon_config(opt.config);
  if (!opt.trajectory.empty()) cfg.trajectory = opt.trajectory;
  if (!std::isnan(opt.duration)) cfg.duration_s = opt.duration;
  const bool has_trajectory = !cfg.trajectory.empty();
  const Trajectory trajectory = Trajectory::parse(has_trajectory ? cfg.trajectory : "hold:0");
  // A local trajectory passes the same [setpoints] checks as one received over DDS (and the envelope at play time).
  if (has_trajectory) trajectory.check_limits(cfg.setpoint_limits);
  control::Controller controller(cfg.rig.model, cfg.rig.controller);
  auto sim = std::make_unique<hal::SimBackend>(cfg.rig.sim);
  if (!opt.inject.empty()) {
    const auto at = opt.inject.find('@');
    const auto kind = hal::parse_sim_fault(opt.inject.substr(0, at));
    if (!kind || at == std::string::npos)
      throw control::ConfigError("--inject-fault", "expected KIND@SECONDS with KIND one of sensor_nan, sensor_stuck, "
                                                   "sensor_out_of_range, sensor_dropout, amplifier_fault, write_failed, "
                                                   "write_timeout, hv_enable_failed; got '" +
                                                       opt.inject + "'");
    const std::string when = opt.inject.substr(at + 1);
    double t_s = NAN;
    const auto [end, ec] = std::from_chars(when.data(), when.data() + when.size(), t_s);
    if (ec != std::errc() || end != when.data() + when.size() || !(t_s >= 0.0))
      throw control::ConfigError("--inject-fault", "'" + when + "' is not a time in seconds (KIND@SECONDS)");
    sim->schedule(*kind, t_s);
  }
  if (opt.check_only) {
    std::cout << "pvcgeld: configuration " << opt.config << " is valid (hash " << cfg.config_hash << ")\n";
    return kExitOk;
  }
  const auto hal_ptr = make_hal(cfg, std::move(sim), !opt.inject.empty());
  hal::Hal& hal = *hal_ptr;

  ControlLoop loop(hal, controller, trajectory, cfg.safety, cfg.realtime.period_s, cfg.duration_s);
  loop.set_auto_start(has_trajectory);
  loop.set_exit_on_fault(std::isfinite(cfg.duration_s));
  loop.set_limits(cfg.setpoint_limits);
  auto io = std::make_unique<LoopIo>();
  if (cfg.dds_enabled) loop.attach_io(*io, cfg.setpoint_limits);

  std::unique_ptr<Recorder> recorder;
  if (!opt.record.empty()) {
    recorder = std::make_unique<Recorder>(
        opt.record, std::vector<std::pair<std::string, std::string>>{
                        {"rate_hz", std::to_string(static_cast<int>(std::lround(1.0 / cfg.realtime.period_s)))},
                        {"config", opt.config},
                        {"config_hash", cfg.config_hash},
                        {"start_time", iso_time_now()},
                        {"hal_backend", std::string(hal.name())},
                        {"trajectory", cfg.trajectory},
                        {"mode", std::string(control::to_string(cfg.rig.controller.mode))},
                        {"soft_start_s", std::to_string(cfg.safety.soft_start_s)}});
  }

  // Signals are taken synchronously by this thread; the loop thread never sees them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGUSR1);  // reset a fault (also a DDS command)
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  RealtimeReport report = prepare_process(cfg.realtime);
  auto stats = std::make_unique<LoopStatistics>();
  auto ring = std::make_unique<RecordRing>();
  auto latest = std::make_unique<LatestRecord>();
  std::atomic<bool> started{false}, loop_done{false};
  // DDS before the loop thread: joining may fail (a configuration error) and nothing may be running then.
  std::unique_ptr<DdsBridge> bridge;
  if (cfg.dds_enabled)
    bridge = std::make_unique<DdsBridge>(cfg.dds, cfg.setpoint_limits, *io, *stats,
                                         DaemonIdentity{cfg.config_hash, PVCGEL_VERSION, std::string(hal.name()),
                                                        cfg.realtime.period_s});
  TelemetryPublisher* publisher = bridge ? &bridge->telemetry() : nullptr;
  std::thread rt([&] {
    run_realtime_loop(loop, cfg.realtime, *stats, *ring, *latest, report, started);
    loop_done.store(true, std::memory_order_release);
  });
  // The one consumer of the loop's records: recording and telemetry, off the RT thread.
  std::exception_ptr writer_error;
  std::thread writer([&] {
    try {
      for (;;) {
        bool any = false;
        while (auto r = ring->pop()) {
          any = true;
          if (recorder) recorder->write(*r);
          if (publisher) publisher->publish(*r);
        }
        if (recorder) recorder->flush_if_due();
        if (!any) {
          if (loop_done.load(std::memory_order_acquire) && ring->size() == 0) break;
          std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
      }
      if (recorder) recorder->finish();
    } catch (...) {
      writer_error = std::current_exception();
    }
  });
  while (!started.load(std::memory_order_acquire)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  if (!report.warnings.empty())
    std::cerr << "pvcgeld: WARNING: " << report.warnings << "\n";
  std::cerr << "pvcgeld: loop running at " << 1.0 / cfg.realtime.period_s << " Hz, "
            << (report.realtime_scheduling ? "SCHED_FIFO priority " + std::to_string(cfg.realtime.priority)
                                           : std::string("NOT real-time (SCHED_OTHER)"))
            << ", memory " << (report.memory_locked ? "locked" : "NOT locked") << ", backend " << hal.name()
            << ", mode " << control::to_string(cfg.rig.controller.mode)
            << (has_trajectory ? ", trajectory " + cfg.trajectory : std::string(", idle (no trajectory)"))
            << (bridge ? ", DDS as rig '" + cfg.dds.rig_id + "' on domain " + std::to_string(cfg.dds.domain)
                          : std::string())
            << "\n";
  sd_notify(0, "READY=1");

  std::uint64_t watchdog_usec = 0;
  const bool watchdog = sd_watchdog_enabled(0, &watchdog_usec) > 0;
  std::uint64_t last_cycles = 0;
  auto last_ping = std::chrono::steady_clock::now();
  bool stop_sent = false, signalled = false;
  LoopState last_state = LoopState::disabled;
  FaultReason last_fault = FaultReason::none;
  auto last_status = last_ping;
  const auto started_at = std::chrono::steady_clock::now();
  while (!loop_done.load(std::memory_order_acquire)) {
    const timespec timeout{0, 20'000'000};
    const int sig = sigtimedwait(&signals, nullptr, &timeout);
    // Without a local trajectory (driven over DDS) --duration bounds the daemon's run time.
    if (!has_trajectory && std::isfinite(cfg.duration_s) && !stop_sent &&
        std::chrono::steady_clock::now() - started_at > std::chrono::duration<double>(cfg.duration_s)) {
      std::cerr << "pvcgeld: --duration reached: ramping down\n";
      loop.request_stop();
      stop_sent = true;
    }
    if (sig == SIGUSR1) {
      std::cerr << "pvcgeld: SIGUSR1: fault reset requested (FAULT -> DISABLED, high voltage off; arm again explicitly)\n";
      loop.request_reset();
    }
    if ((sig == SIGTERM || sig == SIGINT) && !stop_sent) {
      std::cerr << "pvcgeld: " << (sig == SIGTERM ? "SIGTERM" : "SIGINT") << ": ramping down\n";
      sd_notify(0, "STOPPING=1");
      loop.request_stop();
      stop_sent = signalled = true;
    }
    const auto now = std::chrono::steady_clock::now();
    // Log state changes as they happen (the RT thread itself never logs).
    const CycleRecord& rec = latest->read();
    if (rec.state != last_state || rec.fault != last_fault) {
      std::fprintf(stderr, "pvcgeld: t = %.3f s: %s%s%s\n", rec.t_s, to_string(rec.state).data(),
                   rec.fault != FaultReason::none ? ", fault " : "",
                   rec.fault != FaultReason::none ? to_string(rec.fault).data() : "");
      last_state = rec.state;
      last_fault = rec.fault;
    }
    if (now - last_status > std::chrono::seconds(1)) {
      char status[320];
      std::snprintf(status, sizeof status, "STATUS=%s%s%s, u %.1f V, y %.2f um, r %.2f um, %llu overruns, hal %s",
                    to_string(rec.state).data(), rec.fault != FaultReason::none ? " " : "",
                    rec.fault != FaultReason::none ? to_string(rec.fault).data() : "", rec.u_V, rec.y_um, rec.r_um,
                    static_cast<unsigned long long>(stats->overruns.load(std::memory_order_relaxed)),
                    health_summary(hal.health()).c_str());
      sd_notify(0, status);
      last_status = now;
    }
    if (watchdog && now - last_ping > std::chrono::microseconds(watchdog_usec / 2)) {
      // Only a loop that keeps cycling without an overrun storm feeds the watchdog.
      const auto cycles = stats->cycles.load(std::memory_order_relaxed);
      if (cycles > last_cycles && loop.fault() != FaultReason::overrun_storm) sd_notify(0, "WATCHDOG=1");
      last_cycles = cycles;
      last_ping = now;
    }
  }
  rt.join();
  writer.join();
  if (writer_error) std::rethrow_exception(writer_error);

  const auto& s = *stats;
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
                 opt.record.c_str(), static_cast<unsigned long long>(recorder->gaps()));
  std::fprintf(stderr, "; actuator failures %llu, envelope acted on reference %llu / output %llu cycles",
               static_cast<unsigned long long>(loop.actuator_failures()),
               static_cast<unsigned long long>(loop.envelope().reference_limited_cycles()),
               static_cast<unsigned long long>(loop.envelope().output().limited_cycles()));
  std::fprintf(stderr, "; hal %s: %s\n", hal.name().data(), health_summary(hal.health()).c_str());
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
  app.add_option("-d,--duration", opt.duration, "run the trajectory this long (s), then ramp down and exit (without a trajectory: run this long)")
      ->check(CLI::PositiveNumber);
  app.add_option("-r,--record", opt.record, "record every cycle to this CSV file");
  app.add_option("--inject-fault", opt.inject, "sim backend only: KIND@SECONDS, e.g. sensor_nan@3");
  app.add_flag("--check-config", opt.check_only, "validate the configuration and exit");
  CLI11_PARSE(app, argc, argv);
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
