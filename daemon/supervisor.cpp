#include "daemon/supervisor.hpp"

#include <systemd/sd-daemon.h>

#include <cmath>
#include <cstdio>
#include <ctime>

#include "daemon/hal_factory.hpp"

namespace pvcgel::daemon {

sigset_t block_supervised_signals() {
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGUSR1);  // reset a fault (also a DDS command)
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  return signals;
}

Supervisor::Supervisor(ControlLoop& loop, const hal::Hal& hal, const LoopStatistics& stats, LatestRecord& latest,
                       sigset_t signals, double idle_duration_s)
    : loop_(loop), hal_(hal), stats_(stats), latest_(latest), signals_(signals), idle_duration_s_(idle_duration_s) {
  watchdog_ = sd_watchdog_enabled(0, &watchdog_usec_) > 0;
}

bool Supervisor::run(const std::atomic<bool>& loop_done) {
  while (!loop_done.load(std::memory_order_acquire)) {
    const timespec timeout{0, 20'000'000};
    const int sig = sigtimedwait(&signals_, nullptr, &timeout);
    now_ = Clock::now();
    stop_idle_run_when_due();
    take_signal(sig);
    const CycleRecord& rec = latest_.read();
    log_state_change(rec);
    notify_status(rec);
    feed_watchdog();
  }
  return signalled_;
}

void Supervisor::stop_idle_run_when_due() {
  // Without a local trajectory (driven over DDS) --duration bounds the daemon's run time.
  if (!std::isfinite(idle_duration_s_) || stop_sent_ || now_ - started_at_ <= std::chrono::duration<double>(idle_duration_s_))
    return;
  std::fprintf(stderr, "pvcgeld: --duration reached: ramping down\n");
  loop_.request_stop();
  stop_sent_ = true;
}

void Supervisor::take_signal(int sig) {
  if (sig == SIGUSR1) {
    std::fprintf(stderr, "pvcgeld: SIGUSR1: fault reset requested (FAULT -> DISABLED, high voltage off; arm again explicitly)\n");
    loop_.request_reset();
  }
  if ((sig == SIGTERM || sig == SIGINT) && !stop_sent_) {
    std::fprintf(stderr, "pvcgeld: %s: ramping down\n", sig == SIGTERM ? "SIGTERM" : "SIGINT");
    sd_notify(0, "STOPPING=1");
    loop_.request_stop();
    stop_sent_ = signalled_ = true;
  }
}

void Supervisor::log_state_change(const CycleRecord& rec) {
  // The RT thread itself never logs: state changes are logged here as they are seen.
  if (rec.state == last_state_ && rec.fault == last_fault_) return;
  const bool fault = rec.fault != FaultReason::none;
  std::fprintf(stderr, "pvcgeld: t = %.3f s: %s%s%s\n", rec.t_s, to_string(rec.state).data(), fault ? ", fault " : "",
               fault ? to_string(rec.fault).data() : "");
  last_state_ = rec.state;
  last_fault_ = rec.fault;
}

void Supervisor::notify_status(const CycleRecord& rec) {
  if (now_ - last_status_ <= std::chrono::seconds(1)) return;
  const bool fault = rec.fault != FaultReason::none;
  char status[320];
  std::snprintf(status, sizeof status, "STATUS=%s%s%s, u %.1f V, y %.2f um, r %.2f um, %llu overruns, hal %s",
                to_string(rec.state).data(), fault ? " " : "", fault ? to_string(rec.fault).data() : "", rec.u_V,
                rec.y_um, rec.r_um, static_cast<unsigned long long>(stats_.overruns.load(std::memory_order_relaxed)),
                health_summary(hal_.health()).c_str());
  sd_notify(0, status);
  last_status_ = now_;
}

void Supervisor::feed_watchdog() {
  if (!watchdog_ || now_ - last_ping_ <= std::chrono::microseconds(watchdog_usec_ / 2)) return;
  // Only a loop that keeps cycling without an overrun storm feeds the watchdog.
  const auto cycles = stats_.cycles.load(std::memory_order_relaxed);
  if (cycles > last_cycles_ && loop_.fault() != FaultReason::overrun_storm) sd_notify(0, "WATCHDOG=1");
  last_cycles_ = cycles;
  last_ping_ = now_;
}

}  // namespace pvcgel::daemon
