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

int record(const RecordArgs& a) {
  dds::DdsSettings s;
  s.domain = a.domain;
  s.config_path = a.dds_config;
  s.rig_id = a.rig;
  auto participant = dds::make_participant(s);
  dds::Entity topic = dds::make_topic(participant.get(), dds::Topic::telemetry);
  // Reliable keep-all: every sample the daemon's reliable writer sends reaches the file.
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  dds::Entity reader(dds_create_reader(participant.get(), topic.get(), qos, nullptr), "Telemetry reader");
  dds_delete_qos(qos);

  std::signal(SIGINT, [](int) { g_interrupted = 1; });
  std::unique_ptr<daemon::Recorder> recorder;
  std::set<std::string> other_rigs;
  constexpr int kBatch = 256;
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  const auto start = std::chrono::steady_clock::now();
  double first_t = -1.0, last_t = 0.0;
  auto last_sample = start;
  std::uint64_t rows = 0;
  while (!g_interrupted) {
    const int n = dds_take(reader.get(), samples, infos, kBatch, kBatch);
    if (n < 0) throw std::runtime_error(std::string("DDS take failed: ") + dds_strretcode(n));
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* t = static_cast<const pvcgel_v1_Telemetry*>(samples[i]);
      if (a.rig != t->rig_id) {
        other_rigs.insert(t->rig_id);
        continue;
      }
      if (!recorder) {
        recorder = std::make_unique<daemon::Recorder>(
            a.out, daemon::RecordingHeader{{"source", "dds"}, {"rig_id", a.rig}, {"domain", std::to_string(a.domain)}});
        if (!recorder->created_directory().empty())
          std::fprintf(stderr, "pvcgel record: created directory %s\n", recorder->created_directory().c_str());
        first_t = t->t_s;
        std::fprintf(stderr, "pvcgel record: receiving rig '%s' (from cycle %llu)\n", a.rig.c_str(),
                     static_cast<unsigned long long>(t->seq));
      }
      recorder->write(dds::to_cycle_record(*t));
      last_t = t->t_s;
      last_sample = std::chrono::steady_clock::now();
      ++rows;
    }
    if (n > 0) dds_return_loan(reader.get(), samples, n);
    if (recorder) {
      recorder->flush_if_due();
      if (last_t - first_t >= a.duration) break;
      if (std::chrono::steady_clock::now() - last_sample > std::chrono::duration<double>(a.wait)) {
        recorder->finish();  // keep what arrived
        throw std::runtime_error("telemetry stopped after " + format("%.3f", last_t - first_t) + " s of " +
                                 format("%g", a.duration) + " s (daemon gone?); " + std::to_string(rows) +
                                 " rows kept in " + a.out);
      }
    } else if (std::chrono::steady_clock::now() - start > std::chrono::duration<double>(a.wait)) {
      throw no_daemon_error(a.rig, a.domain, a.wait, {other_rigs.begin(), other_rigs.end()},
                            " and reliable_telemetry = true");
    }
    if (n == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  if (!recorder) throw std::runtime_error("interrupted before any sample arrived");
  recorder->finish();
  std::fprintf(stderr, "pvcgel record: %llu rows, %.3f s, sequence gaps %llu -> %s\n",
               static_cast<unsigned long long>(rows), last_t - first_t,
               static_cast<unsigned long long>(recorder->gaps()), a.out.c_str());
  return recorder->gaps() == 0 ? kExitOk : kExitRecordingGap;
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
