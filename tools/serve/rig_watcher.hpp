#pragma once
/// @file
/// The DDS side of `pvcgel serve`: one participant that reads Telemetry,
/// Status and CommandReply of every rig on the domain, on its own thread, and
/// hands each sample to a sink. It only takes from DDS and calls the sink
/// (which must not block); it never waits on a WebSocket client.

#include <atomic>
#include <chrono>
#include <map>
#include <string>

#include "daemon/dds/dds_participant.hpp"
#include "pvcgel_v1.h"
#include "tools/dds_client.hpp"

namespace pvcgel::tools::serve {

/// Receives what the watcher reads. Called on the watcher's thread.
class RigSink {
 public:
  virtual ~RigSink() = default;
  virtual void on_telemetry(const pvcgel_v1_Telemetry& t) = 0;
  virtual void on_status(const pvcgel_v1_Status& s) = 0;
  virtual void on_reply(const pvcgel_v1_CommandReply& r) = 0;
  /// A rig's daemon went quiet (`present` false: no Status for the timeout) or came back.
  virtual void on_presence(const std::string& rig, bool present) = 0;
  /// Called after every burst of samples, at least every 15 ms (batching, housekeeping).
  virtual void on_tick() = 0;
};

class RigWatcher final {
 public:
  /// Joins DDS with `o.dds_config` and `o.domain` (o.rig is not used: every rig is read).
  /// @param reliable_telemetry  a reliable Telemetry reader (needs the daemon's
  ///        reliable_telemetry = true; a best-effort reader matches either writer)
  RigWatcher(const ClientOptions& o, bool reliable_telemetry);
  /// Reads until `stop` is set.
  void run(RigSink& sink, const std::atomic<bool>& stop);

  /// A rig is gone when no Status came for this long (the daemon publishes at >= 2 Hz).
  static constexpr std::chrono::milliseconds kAbsentAfter{2000};

 private:
  template <typename T, typename F>
  void take_all(dds_entity_t reader, F&& each);
  void check_presence(RigSink& sink);

  dds::Entity participant_, telemetry_topic_, status_topic_, reply_topic_;
  dds::Entity telemetry_reader_, status_reader_, reply_reader_, waitset_;
  std::map<std::string, std::chrono::steady_clock::time_point> last_status_;
  std::map<std::string, bool> present_;
};

}  // namespace pvcgel::tools::serve
