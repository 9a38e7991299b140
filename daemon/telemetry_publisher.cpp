#include "daemon/telemetry_publisher.hpp"

#include "daemon/dds/dds_messages.hpp"

namespace pvcgel::daemon {

TelemetryPublisher::TelemetryPublisher(dds_entity_t participant, const dds::DdsSettings& s)
    : rig_id_(s.rig_id), decimation_(s.telemetry_decimation) {
  topic_ = dds::make_topic(participant, dds::Topic::telemetry);
  writer_ = dds::Entity(dds_create_writer(participant, topic_.get(), dds::telemetry_qos(s.reliable_telemetry).get(), nullptr),
                        "Telemetry writer");
}

bool TelemetryPublisher::publish(const CycleRecord& r) noexcept {
  if (decimation_ > 1 && r.seq % static_cast<std::uint64_t>(decimation_) != 0) return true;
  const pvcgel_v1_Telemetry t = dds::to_telemetry(r, rig_id_);
  if (dds_write(writer_.get(), &t) < 0) {
    ++failures_;
    return false;
  }
  return true;
}

}  // namespace pvcgel::daemon
