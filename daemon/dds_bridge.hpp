#pragma once
/// @file
/// The daemon's DDS side: one non-real-time thread that takes trajectories and
/// commands from DDS, validates them and passes them to the loop through
/// lock-free queues, answers each one, and publishes Status. Telemetry goes
/// out through the same participant from the record consumer thread.

#include <array>
#include <deque>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <unordered_map>

#include "daemon/dds/dds_participant.hpp"
#include "daemon/input_validation.hpp"
#include "daemon/loop_io.hpp"
#include "daemon/loop_statistics.hpp"
#include "daemon/telemetry_publisher.hpp"

namespace pvcgel::daemon {

/// Fixed facts about this daemon for Status.
struct DaemonIdentity {
  std::string config_hash;
  std::string version;
  std::string hal_backend;
  double period_s = 1e-3;
};

/// Counters of the bridge (any thread may read).
struct BridgeCounters {
  std::atomic<std::uint64_t> chunks_accepted{0}, commands_accepted{0}, rejects_total{0}, other_rig{0};
  std::array<std::atomic<std::uint32_t>, kRejectReasonNames.size()> rejects_by_reason{};
};

/// Owns the participant, every reader and writer, and the bridge thread.
class DdsBridge final {
 public:
  /// Joins DDS and starts the thread. @throws std::runtime_error when DDS cannot be joined.
  DdsBridge(const dds::DdsSettings& settings, const SetpointLimits& limits, LoopIo& io, const LoopStatistics& stats,
            DaemonIdentity identity);
  /// Stops the thread (publishing a last Status) and leaves DDS.
  ~DdsBridge();
  DdsBridge(const DdsBridge&) = delete;
  DdsBridge& operator=(const DdsBridge&) = delete;

  /// Telemetry writer, for the record consumer thread.
  TelemetryPublisher& telemetry() noexcept { return *telemetry_; }
  [[nodiscard]] const BridgeCounters& counters() const noexcept { return counters_; }
  /// Whether the bridge thread got its real-time priority (known once it runs).
  [[nodiscard]] bool realtime() const noexcept { return realtime_.load(); }

 private:
  struct Pending {
    std::string client_id;
    std::uint64_t seq = 0;
    bool is_trajectory = false;
  };
  void run();
  void take_trajectories();
  void take_commands();
  void drain_outcomes();
  void publish_status(const LoopSnapshot& snap);
  void reply(const std::string& client_id, std::uint64_t seq, bool is_trajectory, RejectReason reason,
             const std::string& detail);
  /// Writes one CommandReply (the only place one is built).
  void write_reply(const std::string& client_id, std::uint64_t seq, bool is_trajectory, RejectReason reason,
                   const std::string& detail);
  void count_reject(RejectReason r, const std::string& detail);
  bool rate_allows(const std::string& client_id, bool trajectory, double now_s);
  /// True when (client, seq) was seen recently: a resend. Answers it again if the answer is known.
  bool is_resend(const std::string& client_id, std::uint64_t seq, bool is_trajectory);

  dds::DdsSettings settings_;
  SetpointLimits limits_;
  LoopIo& io_;
  const LoopStatistics& stats_;
  DaemonIdentity identity_;
  dds::Entity participant_, trajectory_topic_, command_topic_, reply_topic_, status_topic_;
  dds::Entity trajectory_reader_, command_reader_, reply_writer_, status_writer_, waitset_;
  std::unique_ptr<TelemetryPublisher> telemetry_;
  BridgeCounters counters_;
  std::unordered_map<std::uint32_t, Pending> pending_;
  std::unordered_map<std::string, std::pair<RateLimiter, RateLimiter>> limiters_;
  std::unordered_map<std::string, double> last_throttle_reply_s_;
  struct Recent {
    std::uint64_t seq = 0;
    bool is_trajectory = false;
    bool answered = false;
    RejectReason reason = RejectReason::accepted;
    std::string detail;
  };
  std::unordered_map<std::string, std::deque<Recent>> recent_;  // last 32 inputs per client
  std::uint32_t new_ticket() noexcept { return ++next_ticket_ == 0 ? ++next_ticket_ : next_ticket_; }
  std::uint32_t next_ticket_ = 0;
  RejectReason last_reject_reason_ = RejectReason::accepted;
  std::string last_reject_detail_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> realtime_{false};
  std::thread thread_;
};

}  // namespace pvcgel::daemon
