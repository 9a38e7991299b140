#include "tools/serve/rig_watcher.hpp"

#include <stdexcept>
#include <thread>

namespace pvcgel::tools::serve {

namespace {
using Clock = std::chrono::steady_clock;
}

RigWatcher::RigWatcher(const ClientOptions& o, bool reliable_telemetry) {
  participant_ = make_client_participant(o);
  const dds_entity_t p = participant_.get();
  telemetry_topic_ = dds::make_topic(p, dds::Topic::telemetry);
  status_topic_ = dds::make_topic(p, dds::Topic::status);
  reply_topic_ = dds::make_topic(p, dds::Topic::command_reply);
  // The project's QoS, but a deeper reader history: the live-view profile keeps
  // one sample per rig, which a reader woken a little late would overwrite.
  dds::Qos telemetry_qos = dds::telemetry_qos(reliable_telemetry);
  dds_qset_history(telemetry_qos.get(), DDS_HISTORY_KEEP_LAST, 2000);
  telemetry_reader_ = dds::Entity(dds_create_reader(p, telemetry_topic_.get(), telemetry_qos.get(), nullptr),
                                  "Telemetry reader");
  status_reader_ = dds::Entity(dds_create_reader(p, status_topic_.get(), dds::status_qos().get(), nullptr), "Status reader");
  reply_reader_ = dds::Entity(dds_create_reader(p, reply_topic_.get(), dds::reply_qos().get(), nullptr), "CommandReply reader");
  waitset_ = dds::Entity(dds_create_waitset(p), "waitset");
  for (const auto& r : {&telemetry_reader_, &status_reader_, &reply_reader_}) {
    const dds_entity_t cond = dds_create_readcondition(r->get(), DDS_ANY_STATE);
    if (cond < 0 || dds_waitset_attach(waitset_.get(), cond, 0) < 0)
      throw std::runtime_error("cannot attach a DDS read condition to the waitset");
  }
}

template <typename T, typename F>
void RigWatcher::take_all(dds_entity_t reader, F&& each) {
  void* samples[256] = {};
  dds_sample_info_t infos[256];
  for (;;) {
    const int n = dds_take(reader, samples, infos, 256, 256);
    if (n <= 0) return;
    for (int i = 0; i < n; ++i)
      if (infos[i].valid_data) each(*static_cast<const T*>(samples[i]));
    dds_return_loan(reader, samples, n);
  }
}

void RigWatcher::check_presence(RigSink& sink) {
  const auto now = Clock::now();
  for (const auto& [rig, last] : last_status_) {
    const bool present = now - last < kAbsentAfter;
    auto it = present_.find(rig);
    if (it == present_.end() || it->second != present) {
      present_[rig] = present;
      sink.on_presence(rig, present);
    }
  }
}

void RigWatcher::run(RigSink& sink, const std::atomic<bool>& stop) {
  while (!stop.load(std::memory_order_relaxed)) {
    dds_waitset_wait(waitset_.get(), nullptr, 0, DDS_MSECS(10));
    take_all<pvcgel_v1_Status>(status_reader_.get(), [&](const pvcgel_v1_Status& s) {
      last_status_[s.rig_id] = Clock::now();
      sink.on_status(s);
    });
    check_presence(sink);
    take_all<pvcgel_v1_Telemetry>(telemetry_reader_.get(), [&](const pvcgel_v1_Telemetry& t) { sink.on_telemetry(t); });
    take_all<pvcgel_v1_CommandReply>(reply_reader_.get(), [&](const pvcgel_v1_CommandReply& r) { sink.on_reply(r); });
    sink.on_tick();
    // Take samples in bursts of ~4 instead of waking per sample at 1 kHz; the
    // reader history (2000) covers far longer pauses than this.
    std::this_thread::sleep_for(std::chrono::milliseconds(4));
  }
}

}  // namespace pvcgel::tools::serve
