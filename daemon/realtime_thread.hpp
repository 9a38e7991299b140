#pragma once
/// @file
/// The real-time thread: memory locking, SCHED_FIFO, absolute-time wake-ups.

#include <atomic>
#include <string>

#include "daemon/control_loop.hpp"
#include "daemon/loop_statistics.hpp"
#include "daemon/spsc_ring.hpp"
#include "daemon/triple_buffer.hpp"

namespace pvcgel::daemon {

/// Timing and scheduling of the loop thread.
struct RealtimeConfig {
  double period_s = 1e-3;
  int priority = 80;     ///< SCHED_FIFO priority, 1..99
  int cpu = -1;          ///< pin to this CPU; -1: no affinity
  bool lock_memory = true;
  /// Written to /dev/cpu_dma_latency while the daemon runs (keeps CPUs out of
  /// deep idle states, as cyclictest does); negative: leave it alone.
  int cpu_dma_latency_us = 0;
};

/// What the process got from the kernel. Without privileges the loop still
/// runs (in a container, say), but says so loudly.
struct RealtimeReport {
  bool memory_locked = false;
  bool realtime_scheduling = false;
  bool pinned = false;
  int cpu_dma_latency_fd = -1;  ///< held open: closing it restores the default
  std::string warnings;  ///< empty when everything was granted
};

/// Records from the loop to the recorder: 65 s of 1 kHz cycles.
using RecordRing = SpscRing<CycleRecord, 1u << 16>;

/// Latest cycle for status reports (systemd STATUS=, logs): the loop publishes
/// every cycle, readers take the newest whenever they like.
using LatestRecord = TripleBuffer<CycleRecord>;

/// mlockall(MCL_CURRENT | MCL_FUTURE) and the CPU DMA latency request; call
/// once from main before threads start.
RealtimeReport prepare_process(const RealtimeConfig& cfg);

/// Body of the loop thread: applies scheduling and affinity to itself, pre-faults
/// its stack, then runs `loop.cycle()` every period until `loop.finished()`.
/// Each record goes to `records` (a full ring is counted, never waited on) and
/// to `latest`.
/// `report` receives the scheduling outcome before the first cycle.
void run_realtime_loop(ControlLoop& loop, const RealtimeConfig& cfg, LoopStatistics& stats,
                       RecordRing& records, LatestRecord& latest, RealtimeReport& report,
                       std::atomic<bool>& started);

}  // namespace pvcgel::daemon
