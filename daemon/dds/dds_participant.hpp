#pragma once
/// @file
/// Owning handles for Cyclone DDS entities and the shared loopback/config setup.

#include <dds/dds.h>

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
};

/// Name of the Telemetry topic.
inline constexpr const char* kTelemetryTopic = "pvcgel_v1_Telemetry";

/// Creates a participant on `s.domain` configured by `s.config_path` (set as
/// CYCLONEDDS_URI for this process). @throws std::runtime_error.
Entity make_participant(const DdsSettings& s);

}  // namespace pvcgel::dds
