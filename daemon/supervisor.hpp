#pragma once
/// @file
/// pvcgeld's main thread while the loop runs: takes the signals (the loop
/// thread never sees them), bounds an idle run by --duration, logs state
/// changes, and reports to systemd (STATUS=, WATCHDOG=1, STOPPING=1).

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>

#include "daemon/control_loop.hpp"
#include "daemon/loop_statistics.hpp"
#include "daemon/realtime_thread.hpp"
#include "hal/hal.hpp"

namespace pvcgel::daemon {

/// Blocks SIGTERM, SIGINT and SIGUSR1 for the calling thread and every thread
/// it starts afterwards; call before starting any thread.
sigset_t block_supervised_signals();

class Supervisor final {
 public:
  /// @param idle_duration_s  without a local trajectory, ramp down after this long (infinity: never)
  Supervisor(ControlLoop& loop, const hal::Hal& hal, const LoopStatistics& stats, LatestRecord& latest,
             sigset_t signals, double idle_duration_s);

  /// Runs until `loop_done`. @return true when a SIGTERM or SIGINT asked the daemon to stop.
  bool run(const std::atomic<bool>& loop_done);

 private:
  void take_signal(int sig);
  void stop_idle_run_when_due();
  void log_state_change(const CycleRecord& rec);
  void notify_status(const CycleRecord& rec);
  void feed_watchdog();

  using Clock = std::chrono::steady_clock;
  ControlLoop& loop_;
  const hal::Hal& hal_;
  const LoopStatistics& stats_;
  LatestRecord& latest_;
  sigset_t signals_;
  double idle_duration_s_;
  Clock::time_point started_at_ = Clock::now(), now_ = started_at_, last_ping_ = now_, last_status_ = now_;
  std::uint64_t watchdog_usec_ = 0, last_cycles_ = 0;
  bool watchdog_ = false, stop_sent_ = false, signalled_ = false;
  LoopState last_state_ = LoopState::disabled;
  FaultReason last_fault_ = FaultReason::none;
};

}  // namespace pvcgel::daemon
