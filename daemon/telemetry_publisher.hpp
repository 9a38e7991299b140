#pragma once
/// @file
/// Publishes loop records as DDS Telemetry, off the real-time thread.

#include <cstdint>
#include <string>

#include "daemon/control_loop.hpp"
#include "daemon/dds/dds_participant.hpp"

namespace pvcgel::daemon {

/// Writer of the Telemetry topic for one rig.
class TelemetryPublisher final {
 public:
  /// @param participant  an existing participant (owned by the caller, outlives this)
  /// @throws std::runtime_error when the writer cannot be created.
  TelemetryPublisher(dds_entity_t participant, const dds::DdsSettings& settings);
  /// Publish one record (every `telemetry_decimation`-th); false when DDS refused it (counted).
  bool publish(const CycleRecord& r) noexcept;
  /// Samples DDS refused.
  [[nodiscard]] std::uint64_t failures() const noexcept { return failures_; }

 private:
  dds::Entity topic_, writer_;
  std::string rig_id_;
  int decimation_ = 1;
  std::uint64_t failures_ = 0;
};

}  // namespace pvcgel::daemon
