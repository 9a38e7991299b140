#include "daemon/telemetry_publisher.hpp"

#include <cstdio>

#include "pvcgel_v1.h"

namespace pvcgel::daemon {

TelemetryPublisher::TelemetryPublisher(const dds::DdsSettings& s) : rig_id_(s.rig_id) {
  participant_ = dds::make_participant(s);
  topic_ = dds::Entity(dds_create_topic(participant_.get(), &pvcgel_v1_Telemetry_desc, dds::kTelemetryTopic,
                                        nullptr, nullptr),
                       "Telemetry topic");
  dds_qos_t* qos = dds_create_qos();
  if (s.reliable_telemetry) {
    dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
    dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  } else {
    dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
    dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 1);
  }
  writer_ = dds::Entity(dds_create_writer(participant_.get(), topic_.get(), qos, nullptr), "Telemetry writer");
  dds_delete_qos(qos);
}

bool TelemetryPublisher::publish(const CycleRecord& r) noexcept {
  pvcgel_v1_Telemetry t{};
  std::snprintf(t.rig_id, sizeof t.rig_id, "%s", rig_id_.c_str());
  t.seq = r.seq;
  t.t_s = r.t_s;
  t.r_um = r.r_um;
  t.y_um = r.y_um;
  t.u_V = r.u_V;
  t.e_um = r.e_um;
  t.d_hat = r.d_hat;
  t.latency_us = r.latency_us;
  t.mode = static_cast<uint8_t>(r.mode);
  t.state = static_cast<uint8_t>(r.state);
  t.fault = static_cast<uint8_t>(r.fault);
  t.high_voltage = r.high_voltage;
  if (dds_write(writer_.get(), &t) < 0) {
    ++failures_;
    return false;
  }
  return true;
}

}  // namespace pvcgel::daemon
