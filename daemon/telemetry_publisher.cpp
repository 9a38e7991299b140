#include "daemon/telemetry_publisher.hpp"

#include <cstdio>

#include "pvcgel_v1.h"

namespace pvcgel::daemon {

TelemetryPublisher::TelemetryPublisher(dds_entity_t participant, const dds::DdsSettings& s)
    : rig_id_(s.rig_id), decimation_(s.telemetry_decimation) {
  topic_ = dds::Entity(dds_create_topic(participant, &pvcgel_v1_Telemetry_desc, dds::kTelemetryTopic, nullptr, nullptr),
                       "Telemetry topic");
  writer_ = dds::Entity(dds_create_writer(participant, topic_.get(), dds::telemetry_qos(s.reliable_telemetry).get(), nullptr),
                        "Telemetry writer");
}

bool TelemetryPublisher::publish(const CycleRecord& r) noexcept {
  if (decimation_ > 1 && r.seq % static_cast<std::uint64_t>(decimation_) != 0) return true;
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
  t.target = static_cast<uint8_t>(r.target);
  t.chunk_seq = r.chunk_seq;
  t.stamp_ns = r.stamp_ns;
  if (dds_write(writer_.get(), &t) < 0) {
    ++failures_;
    return false;
  }
  return true;
}

}  // namespace pvcgel::daemon
