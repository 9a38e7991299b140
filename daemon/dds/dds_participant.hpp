#pragma once
/// @file
/// Owning handles for Cyclone DDS entities and the shared loopback/config setup.

#include <dds/dds.h>

#include <cstdint>
#include <memory>
#include <string>

namespace pvcgel::dds {

/// Owns a dds_entity_t; deleting the participant deletes its children.
class Entity final {
 public:
  Entity() = default;
  /// @throws std::runtime_error with `what` and Cyclone's error text if `e` is an error code.
  Entity(dds_entity_t e, const char* what);
  ~Entity();
  Entity(Entity&& o) noexcept : e_(o.e_) { o.e_ = 0; }
  Entity& operator=(Entity&& o) noexcept;
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;
  [[nodiscard]] dds_entity_t get() const noexcept { return e_; }

 private:
  dds_entity_t e_ = 0;
};

/// Where and how to join DDS.
struct DdsSettings {
  int domain = 0;
  /// Cyclone DDS XML configuration (file path). Required: the default
  /// configuration would discover over every multicast interface.
  std::string config_path;
  std::string rig_id = "rig1";
  bool reliable_telemetry = false;
  /// Publish every n-th cycle (1: every cycle).
  int telemetry_decimation = 1;
  /// SCHED_FIFO priority for Cyclone's receive and delivery threads and the
  /// daemon's DDS bridge (below the loop's); 0: normal scheduling.
  int realtime_priority = 0;
};

/// Topic names (the IDL documents each).
inline constexpr const char* kTelemetryTopic = "pvcgel_v1_Telemetry";
inline constexpr const char* kTrajectoryTopic = "pvcgel_v1_Trajectory";
inline constexpr const char* kCommandTopic = "pvcgel_v1_Command";
inline constexpr const char* kCommandReplyTopic = "pvcgel_v1_CommandReply";
inline constexpr const char* kStatusTopic = "pvcgel_v1_Status";

/// The five topics of the IDL, created by make_topic with their type and name.
enum class Topic : std::uint8_t { telemetry, trajectory, command, command_reply, status };

/// Creates `topic` on `participant`. @throws std::runtime_error naming the topic.
Entity make_topic(dds_entity_t participant, Topic topic);

/// Owned dds_qos_t.
struct QosDeleter {
  void operator()(dds_qos_t* q) const noexcept { dds_delete_qos(q); }
};
using Qos = std::unique_ptr<dds_qos_t, QosDeleter>;

/// QoS of each topic, the same for the daemon and every client (see the IDL).
/// Readers and writers take the same profile; `reader` selects the reader side
/// where the two differ (bounded keep-last readers on the daemon's inputs).
Qos telemetry_qos(bool reliable);
Qos trajectory_qos(bool reader);
Qos command_qos(bool reader);
Qos reply_qos();
Qos status_qos();

/// Creates a participant on `s.domain` configured by `s.config_path` (set as
/// CYCLONEDDS_URI for this process). @throws std::runtime_error.
Entity make_participant(const DdsSettings& s);

}  // namespace pvcgel::dds
