#include "tools/record_command.hpp"
#include "tools/exit_codes.hpp"

#include <chrono>
#include <csignal>
#include <cstdio>
#include <memory>
#include <set>
#include <stdexcept>
#include <thread>

#include "daemon/dds/dds_messages.hpp"
#include "daemon/dds/dds_participant.hpp"
#include "daemon/recorder.hpp"
#include "tools/dds_client.hpp"
#include "tools/text_output.hpp"
#include "pvcgel_v1.h"

namespace pvcgel::tools {

namespace {

struct RecordArgs {
  std::string out, rig = "rig1", dds_config;
  int domain = 0;
  double duration = 10.0, wait = 5.0;
};

volatile std::sig_atomic_t g_interrupted = 0;

/// A reliable keep-all Telemetry reader: every sample the daemon's reliable writer sends reaches the file.
dds::Entity make_telemetry_reader(dds_entity_t participant, dds_entity_t topic) {
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  dds::Entity reader(dds_create_reader(participant, topic, qos, nullptr), "Telemetry reader");
  dds_delete_qos(qos);
  return reader;
}

/// The rig's telemetry as it arrives: the file, opened on its first sample, and the span and rows written;
/// other rigs' samples are only noted (for the error when ours never comes).
class TelemetryFile {
 public:
  explicit TelemetryFile(const RecordArgs& a) : a_(a) {}

  void add(const pvcgel_v1_Telemetry& t) {
    if (a_.rig != t.rig_id) {
      other_rigs_.insert(t.rig_id);
      return;
    }
    if (!recorder_) open(t);
    recorder_->write(dds::to_cycle_record(t));
    last_t_ = t.t_s;
    last_sample_ = std::chrono::steady_clock::now();
    ++rows_;
  }

  /// Whether the asked duration is recorded; throws when no sample came within --wait (no daemon) or the
  /// stream stopped for --wait (what arrived is kept).
  bool complete(std::chrono::steady_clock::time_point start) {
    const auto waited = [&](auto since) { return std::chrono::steady_clock::now() - since > std::chrono::duration<double>(a_.wait); };
    if (!recorder_) {
      if (waited(start))
        throw no_daemon_error(a_.rig, a_.domain, a_.wait, {other_rigs_.begin(), other_rigs_.end()}, " and reliable_telemetry = true");
      return false;
    }
    recorder_->flush_if_due();
    if (last_t_ - first_t_ >= a_.duration) return true;
    if (waited(last_sample_)) {
      recorder_->finish();
      throw std::runtime_error("telemetry stopped after " + format("%.3f", last_t_ - first_t_) + " s of " +
                               format("%g", a_.duration) + " s (daemon gone?); " + std::to_string(rows_) + " rows kept in " + a_.out);
    }
    return false;
  }

  /// Closes the file and reports it; the exit code says whether the sequence had gaps.
  int finish() {
    if (!recorder_) throw std::runtime_error("interrupted before any sample arrived");
    recorder_->finish();
    std::fprintf(stderr, "pvcgel record: %llu rows, %.3f s, sequence gaps %llu -> %s\n", static_cast<unsigned long long>(rows_),
                 last_t_ - first_t_, static_cast<unsigned long long>(recorder_->gaps()), a_.out.c_str());
    return recorder_->gaps() == 0 ? kExitOk : kExitRecordingGap;
  }

 private:
  void open(const pvcgel_v1_Telemetry& t) {
    recorder_ = std::make_unique<daemon::Recorder>(
        a_.out, daemon::RecordingHeader{{"source", "dds"}, {"rig_id", a_.rig}, {"domain", std::to_string(a_.domain)}});
    if (!recorder_->created_directory().empty())
      std::fprintf(stderr, "pvcgel record: created directory %s\n", recorder_->created_directory().c_str());
    first_t_ = t.t_s;
    std::fprintf(stderr, "pvcgel record: receiving rig '%s' (from cycle %llu)\n", a_.rig.c_str(),
                 static_cast<unsigned long long>(t.seq));
  }

  const RecordArgs& a_;
  std::unique_ptr<daemon::Recorder> recorder_;
  std::set<std::string> other_rigs_;
  double first_t_ = -1.0, last_t_ = 0.0;
  std::chrono::steady_clock::time_point last_sample_;
  std::uint64_t rows_ = 0;
};

/// Takes what the reader holds (up to a batch) into `file`; returns how many samples that was.
int take_batch(const dds::Entity& reader, TelemetryFile& file) {
  constexpr int kBatch = 256;
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  const int n = dds_take(reader.get(), samples, infos, kBatch, kBatch);
  if (n < 0) throw std::runtime_error(std::string("DDS take failed: ") + dds_strretcode(n));
  for (int i = 0; i < n; ++i)
    if (infos[i].valid_data) file.add(*static_cast<const pvcgel_v1_Telemetry*>(samples[i]));
  if (n > 0) dds_return_loan(reader.get(), samples, n);
  return n;
}

int record(const RecordArgs& a) {
  dds::DdsSettings s;
  s.domain = a.domain;
  s.config_path = a.dds_config;
  s.rig_id = a.rig;
  auto participant = dds::make_participant(s);
  dds::Entity topic = dds::make_topic(participant.get(), dds::Topic::telemetry);
  const dds::Entity reader = make_telemetry_reader(participant.get(), topic.get());
  std::signal(SIGINT, [](int) { g_interrupted = 1; });
  TelemetryFile file(a);
  const auto start = std::chrono::steady_clock::now();
  while (!g_interrupted) {
    const int n = take_batch(reader, file);
    if (file.complete(start)) break;
    if (n == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return file.finish();
}

}  // namespace

void add_record_command(CLI::App& app) {
  auto args = std::make_shared<RecordArgs>();
  auto* cmd = app.add_subcommand("record", "Record a rig's telemetry over DDS, lossless (reliable reader, gap check)");
  cmd->add_option("--out", args->out, "recording CSV to write (the daemon's format)")->required();
  cmd->add_option("--duration", args->duration, "seconds of telemetry to record")->capture_default_str()->check(CLI::PositiveNumber);
  auto client = std::make_shared<ClientOptions>();
  add_client_options(*cmd, *client);
  cmd->callback([args, client] {
    args->rig = client->rig;
    args->domain = client->domain;
    args->dds_config = client->dds_config;
    args->wait = client->wait_s;
    if (args->dds_config.empty())
      throw CLI::ValidationError("--dds-config", "no DDS configuration: pass --dds-config FILE or set PVCGEL_DDS_CONFIG");
    const int rc = record(*args);
    if (rc != 0) throw CLI::RuntimeError(rc);
  });
}

}  // namespace pvcgel::tools
