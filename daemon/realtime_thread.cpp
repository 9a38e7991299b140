#include "daemon/realtime_thread.hpp"

#include <pthread.h>
#include <sched.h>
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>
#include <time.h>

#include <cerrno>
#include <cmath>
#include <cstring>

namespace pvcgel::daemon {

namespace {
constexpr std::int64_t kNsPerS = 1'000'000'000;

std::int64_t now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerS + ts.tv_nsec;
}

timespec to_timespec(std::int64_t ns) noexcept {
  return {static_cast<time_t>(ns / kNsPerS), static_cast<long>(ns % kNsPerS)};
}

// Touch the stack now so the loop never takes a page fault growing it.
void prefault_stack() noexcept {
  constexpr std::size_t kBytes = 256 * 1024;
  volatile unsigned char buffer[kBytes];
  for (std::size_t i = 0; i < kBytes; i += 4096) buffer[i] = 0;
  (void)buffer[0];
}
}  // namespace

RealtimeReport prepare_process(const RealtimeConfig& cfg) {
  RealtimeReport r;
  if (!cfg.lock_memory) {
    r.warnings += "memory locking disabled by configuration; ";
  } else if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
    r.memory_locked = true;
  } else {
    r.warnings += std::string("mlockall failed (") + std::strerror(errno) +
                  "): page faults may stall the loop (needs CAP_IPC_LOCK or LimitMEMLOCK=infinity); ";
  }
  if (cfg.cpu_dma_latency_us >= 0) {
    const int fd = open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
    const std::int32_t value = cfg.cpu_dma_latency_us;
    if (fd >= 0 && write(fd, &value, sizeof value) == static_cast<ssize_t>(sizeof value)) {
      r.cpu_dma_latency_fd = fd;  // the request lasts while the file stays open
    } else {
      if (fd >= 0) close(fd);
      r.warnings += "could not set /dev/cpu_dma_latency (deep CPU idle states may add wake-up latency); ";
    }
  }
  return r;
}

namespace {

/// SCHED_FIFO at cfg.priority and the CPU pin, on the calling thread, before its loop starts (not the RT path:
/// a refusal is a warning in `report`, and the loop runs best effort).
void claim_realtime_thread(const RealtimeConfig& cfg, RealtimeReport& report) {
  sched_param sp{};
  sp.sched_priority = cfg.priority;
  const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  if (rc == 0) {
    report.realtime_scheduling = true;
  } else {
    report.warnings += std::string("SCHED_FIFO priority ") + std::to_string(cfg.priority) + " refused (" +
                       std::strerror(rc) + "): running WITHOUT real-time scheduling, timing is best effort "
                       "(needs CAP_SYS_NICE / LimitRTPRIO); ";
  }
  if (cfg.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cfg.cpu, &set);
    if (pthread_setaffinity_np(pthread_self(), sizeof set, &set) == 0) report.pinned = true;
    else report.warnings += "CPU affinity to " + std::to_string(cfg.cpu) + " refused; ";
  }
}

}  // namespace

void run_realtime_loop(ControlLoop& loop, const RealtimeConfig& cfg, LoopStatistics& stats, RecordRing& records,
                       LatestRecord& latest, RealtimeReport& report, std::atomic<bool>& started) {
  claim_realtime_thread(cfg, report);
  prefault_stack();
  started.store(true, std::memory_order_release);

  const auto period_ns = static_cast<std::int64_t>(std::llround(cfg.period_s * 1e9));
  std::int64_t deadline = now_ns() + period_ns;
  int consecutive_overruns = 0;
  while (!loop.finished()) {
    const timespec ts = to_timespec(deadline);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
    const std::int64_t woke = now_ns();
    const std::int64_t latency = woke - deadline;
    stats.wakeup_latency.add(latency);
    CycleRecord rec = loop.cycle(static_cast<float>(latency) * 1e-3f, consecutive_overruns);
    timespec wall{};
    clock_gettime(CLOCK_REALTIME, &wall);
    rec.stamp_ns = static_cast<std::int64_t>(wall.tv_sec) * kNsPerS + wall.tv_nsec;
    if (!records.push(rec)) stats.records_dropped.fetch_add(1, std::memory_order_relaxed);
    latest.write(rec);
    const std::int64_t done = now_ns();
    stats.compute_time.add(done - woke);
    stats.cycles.fetch_add(1, std::memory_order_relaxed);
    deadline += period_ns;
    if (done > deadline) {
      // Missed at least one period: count it and re-align to the next future
      // period instead of firing a burst of late cycles.
      stats.overruns.fetch_add(1, std::memory_order_relaxed);
      ++consecutive_overruns;
      const std::int64_t missed = (done - deadline) / period_ns + 1;
      deadline += missed * period_ns;
    } else {
      consecutive_overruns = 0;
    }
  }
}

}  // namespace pvcgel::daemon
