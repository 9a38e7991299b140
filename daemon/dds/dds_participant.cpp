#include "daemon/dds/dds_participant.hpp"

#include <cstdlib>
#include <filesystem>
#include <iterator>
#include <stdexcept>

#include "pvcgel_v1.h"

namespace pvcgel::dds {

Entity::Entity(dds_entity_t e, const char* what) : e_(e) {
  if (e < 0) {
    e_ = 0;
    throw std::runtime_error(std::string("DDS: cannot create ") + what + ": " + dds_strretcode(e));
  }
}

Entity::~Entity() {
  if (e_ > 0) dds_delete(e_);
}

Entity& Entity::operator=(Entity&& o) noexcept {
  if (this != &o) {
    if (e_ > 0) dds_delete(e_);
    e_ = o.e_;
    o.e_ = 0;
  }
  return *this;
}

Entity make_participant(const DdsSettings& s) {
  if (s.config_path.empty())
    throw std::runtime_error("DDS: no Cyclone DDS configuration given (dds.config / --dds-config); refusing to "
                             "start with the default, which discovers over every multicast interface");
  if (!std::filesystem::exists(s.config_path))
    throw std::runtime_error("DDS: configuration file '" + s.config_path + "' not found");
  std::string uri = "file://" + std::filesystem::absolute(s.config_path).string();
  if (s.realtime_priority > 0) {
    // Setpoints arrive through these threads: give them real-time priority so
    // a busy machine does not delay them (the loop itself stays above them).
    std::string threads;
    for (const char* name : {"recv", "dq.user"})
      threads += std::string("<Thread name=\"") + name + "\"><Scheduling><Class>realtime</Class><Priority>" +
                 std::to_string(s.realtime_priority) + "</Priority></Scheduling></Thread>";
    uri += ",<CycloneDDS><Domain id=\"any\"><Threads>" + threads + "</Threads></Domain></CycloneDDS>";
  }
  setenv("CYCLONEDDS_URI", uri.c_str(), 1);
  return Entity(dds_create_participant(static_cast<dds_domainid_t>(s.domain), nullptr, nullptr), "participant");
}

namespace {
Qos reliable_qos() {
  Qos q(dds_create_qos());
  dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  return q;
}
}  // namespace

Qos telemetry_qos(bool reliable) {
  Qos q(dds_create_qos());
  if (reliable) {
    dds_qset_reliability(q.get(), DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(q.get(), DDS_HISTORY_KEEP_ALL, 0);
  } else {
    dds_qset_reliability(q.get(), DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 1);
  }
  return q;
}

Qos trajectory_qos(bool reader) {
  // Reliable so chunks are not lost; the daemon's reader keeps at most 64 per
  // rig, which bounds what a client can make it hold.
  Qos q = reliable_qos();
  if (reader) dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 64);
  else dds_qset_history(q.get(), DDS_HISTORY_KEEP_ALL, 0);
  return q;
}

Qos command_qos(bool reader) {
  Qos q = reliable_qos();
  if (reader) dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 16);
  else dds_qset_history(q.get(), DDS_HISTORY_KEEP_ALL, 0);
  return q;
}

Qos reply_qos() {
  Qos q = reliable_qos();
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 64);
  return q;
}

Qos status_qos() {
  // Transient-local keep-last(1): a client that joins late gets the latest status at once.
  Qos q = reliable_qos();
  dds_qset_durability(q.get(), DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(q.get(), DDS_HISTORY_KEEP_LAST, 1);
  return q;
}

Entity make_topic(dds_entity_t participant, Topic topic) {
  struct Spec {
    const dds_topic_descriptor_t* type;
    const char* name;
    const char* what;
  };
  static constexpr Spec kSpecs[] = {{&pvcgel_v1_Telemetry_desc, kTelemetryTopic, "Telemetry topic"},
                                    {&pvcgel_v1_Trajectory_desc, kTrajectoryTopic, "Trajectory topic"},
                                    {&pvcgel_v1_Command_desc, kCommandTopic, "Command topic"},
                                    {&pvcgel_v1_CommandReply_desc, kCommandReplyTopic, "CommandReply topic"},
                                    {&pvcgel_v1_Status_desc, kStatusTopic, "Status topic"}};
  static_assert(std::size(kSpecs) == static_cast<std::size_t>(Topic::status) + 1);
  const Spec& spec = kSpecs[static_cast<std::size_t>(topic)];
  return Entity(dds_create_topic(participant, spec.type, spec.name, nullptr, nullptr), spec.what);
}

}  // namespace pvcgel::dds
