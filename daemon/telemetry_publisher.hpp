#pragma once
/// @file
/// Publishes loop records as pvcgel::v1::Telemetry (off the real-time thread).

#include "daemon/control_loop.hpp"
#include "daemon/dds/dds_participant.hpp"

namespace pvcgel::daemon {

/// One DDS writer for the Telemetry topic, keyed by rig id. QoS: best-effort
/// keep-last(1) by default (live views never slow anything down); reliable
/// keep-all when `reliable_telemetry` is set, so `pvcgel record` is lossless.
class TelemetryPublisher final {
 public:
  /// @throws std::runtime_error when DDS cannot be joined.
  explicit TelemetryPublisher(const dds::DdsSettings& settings);
  /// Publish one record; returns false when DDS refused it (counted).
  bool publish(const CycleRecord& r) noexcept;
  /// Samples DDS refused.
  [[nodiscard]] std::uint64_t failures() const noexcept { return failures_; }

 private:
  dds::Entity participant_, topic_, writer_;
  std::string rig_id_;
  std::uint64_t failures_ = 0;
};

}  // namespace pvcgel::daemon
