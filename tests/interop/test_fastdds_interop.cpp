// Interoperability: a Fast DDS client (tests/interop/fastdds_client.cpp, types
// from fastddsgen) against the real pvcgeld (Cyclone DDS), and against this
// test process as a Cyclone peer for a field-by-field check of every topic.
// All on loopback, DDS domain 7 (no other test uses it).
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include "daemon/dds/dds_participant.hpp"
#include "tests/support/subprocess.hpp"
#include "pvcgel_v1.h"

namespace {

using pvcgel::test::Process;
constexpr int kDomain = 7;
const std::string kDaemon = PVCGELD_PATH;
const std::string kClient = FASTDDS_CLIENT_PATH;
const std::string kSourceDir = PVCGEL_SOURCE_DIR;
const std::string kCycloneXml = kSourceDir + "/config/cyclonedds-loopback.xml";
const std::string kFastDdsXml = kSourceDir + "/config/fastdds-loopback.xml";

std::string temp_path(const std::string& name) {
  return ::testing::TempDir() + "interop_" + std::to_string(getpid()) + "_" + name;
}

/// The shipped sim config with DDS on domain 7 as `rig_id`, the loopback XML,
/// reliable (or best-effort) telemetry, and the start-up trajectory replaced (or removed).
std::string daemon_config(const std::string& rig_id, const std::string& trajectory, bool reliable_telemetry = true) {
  std::string text = pvcgel::test::slurp(kSourceDir + "/config/pvcgeld-sim.toml");
  // Replaces the first line of table `table` that starts with `starts`.
  const auto replace_line = [&](const std::string& table, const std::string& starts, const std::string& line) {
    const auto header = text.find("\n[" + table + "]\n");
    const auto pos = header == std::string::npos ? header : text.find("\n" + starts, header + 1);
    if (pos == std::string::npos || pos > text.find("\n[", header + 1))
      throw std::runtime_error("sim config has no line starting with '" + starts + "' in [" + table + "]");
    text.replace(pos + 1, text.find('\n', pos + 1) - pos - 1, line);
  };
  replace_line("dds", "enabled = ", "enabled = true");
  replace_line("dds", "domain = ", "domain = " + std::to_string(kDomain));
  replace_line("dds", "rig_id = ", "rig_id = \"" + rig_id + "\"");
  replace_line("dds", "reliable_telemetry = ", reliable_telemetry ? "reliable_telemetry = true" : "reliable_telemetry = false");
  replace_line("dds", "config = ", "config = \"" + kCycloneXml + "\"");
  replace_line("run", "trajectory = ", trajectory.empty() ? "" : "trajectory = \"" + trajectory + "\"");
  const std::string path = temp_path(rig_id + ".toml");
  std::ofstream(path) << text;
  return path;
}

/// A CSV with a header row, numeric columns.
struct Csv {
  std::map<std::string, std::vector<double>> cols;
  size_t rows = 0;
  [[nodiscard]] const std::vector<double>& col(const std::string& name) const { return cols.at(name); }
};

Csv read_csv(const std::string& path) {
  std::ifstream f(path);
  std::string line;
  Csv csv;
  std::vector<std::string> names;
  if (!std::getline(f, line)) return csv;
  std::stringstream header(line);
  for (std::string n; std::getline(header, n, ',');) names.push_back(n);
  while (std::getline(f, line)) {
    std::stringstream row(line);
    size_t i = 0;
    for (std::string cell; std::getline(row, cell, ',') && i < names.size(); ++i)
      csv.cols[names[i]].push_back(std::stod(cell));
    ++csv.rows;
  }
  return csv;
}

/// Every received sequence number follows its predecessor, and loop time with it.
void expect_gapless(const Csv& t, double period_s) {
  const auto& seq = t.col("seq");
  const auto& time = t.col("t_s");
  size_t gaps = 0;
  for (size_t k = 1; k < seq.size(); ++k)
    if (seq[k] != seq[k - 1] + 1 || std::abs(time[k] - time[k - 1] - period_s) > 1e-9) ++gaps;
  EXPECT_EQ(gaps, 0u) << "of " << seq.size() << " samples";
}

/// The fields are where the IDL says: e = r - y holds in what Fast DDS decoded.
void expect_consistent_fields(const Csv& t) {
  const auto& r = t.col("r_um");
  const auto& y = t.col("y_um");
  const auto& e = t.col("e_um");
  const auto now_ns = std::chrono::duration<double, std::nano>(std::chrono::system_clock::now().time_since_epoch()).count();
  for (size_t k = 0; k < t.rows; ++k) {
    ASSERT_NEAR(e[k], r[k] - y[k], 1e-9) << "row " << k;
    ASSERT_TRUE(std::isfinite(y[k]) && y[k] > -50.0 && y[k] < 1000.0) << "row " << k << " y " << y[k];
    ASSERT_LE(t.col("state")[k], 4.0);
    ASSERT_LE(t.col("mode")[k], 3.0);
    ASSERT_NEAR(t.col("stamp_ns")[k], now_ns, 120e9) << "CLOCK_REALTIME stamp within two minutes of now";
  }
}

/// UDP sockets of `pid` bound to anything but 127.0.0.1 or 0.0.0.0, from /proc.
std::vector<std::string> non_loopback_sockets(pid_t pid) {
  std::set<std::string> inodes;
  const std::string fd_dir = "/proc/" + std::to_string(pid) + "/fd";
  for (const auto& entry : std::filesystem::directory_iterator(fd_dir)) {
    std::error_code ec;
    const auto target = std::filesystem::read_symlink(entry.path(), ec).string();
    if (!ec && target.rfind("socket:[", 0) == 0) inodes.insert(target.substr(8, target.size() - 9));
  }
  std::vector<std::string> bad;
  for (const char* table : {"/udp", "/udp6"}) {
    std::ifstream f("/proc/" + std::to_string(pid) + "/net" + table);
    std::string line;
    std::getline(f, line);
    while (std::getline(f, line)) {
      std::stringstream s(line);
      std::string sl, local, remote, st, queues, tr, retr, uid, timeout, inode;
      s >> sl >> local >> remote >> st >> queues >> tr >> retr >> uid >> timeout >> inode;
      if (!inodes.count(inode)) continue;
      const std::string addr = local.substr(0, local.find(':'));
      if (addr != "0100007F" && addr != "00000000") bad.push_back(std::string(table) + " " + local);
    }
  }
  return bad;
}

/// Multicast groups joined on any interface besides the all-hosts group every interface has.
std::vector<std::string> joined_multicast_groups() {
  std::ifstream f("/proc/net/igmp");
  std::vector<std::string> groups;
  std::string line;
  while (std::getline(f, line)) {
    std::stringstream s(line);
    std::string group;
    s >> group;
    if (line[0] == '\t' && group.size() == 8 && group != "010000E0") groups.push_back(group);
  }
  return groups;
}

TEST(FastDdsInterop, ReceivesDaemonTelemetryGaplessAndStaysOnLoopback) {
  const std::string csv_path = temp_path("listen.csv");
  Process daemon(kDaemon, {"--config", daemon_config("interop_rig_a", "paper-0.5hz"), "--duration", "12"});
  Process client(kClient,
               {"--profile", kFastDdsXml, "--domain", std::to_string(kDomain), "--rig", "interop_rig_a", "--wait", "10",
                "listen", "--out", csv_path, "--duration", "5"});
  // While both run: nothing bound outside loopback, no multicast group joined.
  std::this_thread::sleep_for(std::chrono::seconds(3));
  for (const pid_t pid : {daemon.pid(), client.pid()}) {
    ASSERT_GT(pid, 0);
    EXPECT_EQ(non_loopback_sockets(pid), std::vector<std::string>{}) << "pid " << pid;
  }
  EXPECT_EQ(joined_multicast_groups(), std::vector<std::string>{}) << "see /proc/net/igmp";

  const auto client_result = client.wait();
  ASSERT_EQ(client_result.exit_code, 0) << client_result.err;
  const auto daemon_result = daemon.stop();
  EXPECT_EQ(daemon_result.exit_code, 0) << daemon_result.err;
  const Csv t = read_csv(csv_path);
  std::cout << "[interop] Fast DDS received " << t.rows << " telemetry samples from pvcgeld\n";
  ASSERT_GE(t.rows, 4500u) << "5 s at 1 kHz";
  expect_gapless(t, 0.001);
  expect_consistent_fields(t);
  // The paper reference, tracked: the values are the loop's, not garbage that happens to decode.
  double worst_e = 0.0, r_min = 1e9, r_max = -1e9;
  const auto& state = t.col("state");
  size_t running = 0;
  for (size_t k = 0; k < t.rows; ++k) {
    if (state[k] != 2.0) {
      ASSERT_EQ(running, 0u) << "left RUNNING at row " << k;  // only the auto-start may precede it
      continue;
    }
    ++running;
    EXPECT_EQ(t.col("high_voltage")[k], 1.0);
    if (t.col("t_s")[k] < 4.0) continue;  // soft start, settling
    worst_e = std::max(worst_e, std::abs(t.col("e_um")[k]));
    r_min = std::min(r_min, t.col("r_um")[k]);
    r_max = std::max(r_max, t.col("r_um")[k]);
  }
  std::cout << "[interop] after t = 4 s: r in [" << r_min << ", " << r_max << "] um, max |e| " << worst_e << " um\n";
  EXPECT_LT(worst_e, 2.0) << "the daemon e2e test's bound for paper-0.5hz";
  EXPECT_GT(r_max - r_min, 10.0) << "a moving reference";
  EXPECT_GE(running, t.rows - 100) << "RUNNING from the auto-start on";
}

// The daemon's default telemetry QoS (best-effort keep-last 1) with a
// best-effort Fast DDS reader, as a live view would use: it matches, and on
// loopback nearly every cycle arrives, in order.
TEST(FastDdsInterop, ReceivesBestEffortTelemetry) {
  const std::string csv_path = temp_path("listen_be.csv");
  Process daemon(kDaemon, {"--config", daemon_config("interop_rig_d", "paper-0.5hz", false), "--duration", "30"});
  Process client(kClient,
                      {"--profile", kFastDdsXml, "--domain", std::to_string(kDomain), "--rig", "interop_rig_d", "--wait",
                       "10", "listen", "--best-effort", "--out", csv_path, "--duration", "3"});
  const auto client_result = client.wait();
  ASSERT_EQ(client_result.exit_code, 0) << client_result.err;
  const auto daemon_result = daemon.stop();
  EXPECT_EQ(daemon_result.exit_code, 0) << daemon_result.err;
  const Csv t = read_csv(csv_path);
  ASSERT_GT(t.rows, 0u);
  const auto& seq = t.col("seq");
  for (size_t k = 1; k < t.rows; ++k) ASSERT_GT(seq[k], seq[k - 1]) << "row " << k;
  const double span = seq.back() - seq.front() + 1;
  std::cout << "[interop] best effort: " << t.rows << " of " << span << " cycles received\n";
  EXPECT_GE(static_cast<double>(t.rows), 0.9 * span);
  EXPECT_GE(span, 2500.0) << "about 3 s at 1 kHz";
  expect_consistent_fields(t);
}

// The Fast DDS client arms and starts the idle daemon, holds 60 um, plays a
// sine from there and stops; every step is answered and executed, and the
// daemon's Status counts it. A second daemon on the domain, another rig id,
// is addressed by none of it.
TEST(FastDdsInterop, TrajectoryFromFastDdsIsAcceptedAndExecuted) {
  const std::string csv_path = temp_path("drive.csv");
  Process daemon(kDaemon, {"--config", daemon_config("interop_rig_c", ""), "--duration", "60"});
  Process bystander(kDaemon, {"--config", daemon_config("interop_rig_other", ""), "--duration", "60"});
  Process client(kClient,
                      {"--profile", kFastDdsXml, "--domain", std::to_string(kDomain), "--rig", "interop_rig_c", "--wait",
                       "10", "drive", "--out", csv_path, "--level", "60", "--blend", "1", "--hold", "3", "--amplitude",
                       "20", "--freq", "0.5", "--sine", "4"});
  const auto client_result = client.wait();
  ASSERT_EQ(client_result.exit_code, 0) << client_result.out << client_result.err << "\ndaemon:\n" << daemon.err_so_far();
  const auto daemon_result = daemon.stop();
  EXPECT_EQ(daemon_result.exit_code, 0) << daemon_result.err;
  const auto bystander_result = bystander.stop();
  EXPECT_EQ(bystander_result.exit_code, 0) << bystander_result.err;
  EXPECT_EQ(bystander_result.err.find("ARMED"), std::string::npos) << bystander_result.err;
  EXPECT_EQ(bystander_result.err.find("RUNNING"), std::string::npos) << bystander_result.err;
  // Its telemetry reached the client too, told apart by the key.
  const auto other = client_result.out.find("other rigs ");
  ASSERT_NE(other, std::string::npos) << client_result.out;
  EXPECT_GT(std::stoul(client_result.out.substr(other + 11)), 1000u) << client_result.out;

  // Every command and chunk answered "accepted" by the daemon over CommandReply.
  const std::string& out = client_result.out;
  for (const char* reply : {"seq=1 is_trajectory=0 accepted=1", "seq=2 is_trajectory=0 accepted=1",
                            "seq=1 is_trajectory=1 accepted=1", "seq=2 is_trajectory=1 accepted=1",
                            "seq=3 is_trajectory=0 accepted=1"})
    EXPECT_NE(out.find("reply rig_id=interop_rig_c client_id=fastdds-interop " + std::string(reply)), std::string::npos)
        << reply << "\n" << out;

  // Status (reliable, transient-local) from the daemon counts what the client
  // sent as the replies did (3 commands, 2 chunks, 0 refusals; a request the
  // client had to send again is answered again but counted once, by both).
  const auto counts = out.find("replies commands_accepted=");
  ASSERT_NE(counts, std::string::npos) << out;
  std::stringstream fields(out.substr(counts + 8, out.find('\n', counts) - counts - 8));
  const auto status = out.find("status rig_id=interop_rig_c ");
  ASSERT_NE(status, std::string::npos) << out;
  const std::string status_line = out.substr(status, out.find('\n', status) - status) + " ";
  for (std::string field; fields >> field;) EXPECT_NE(status_line.find(" " + field + " "), std::string::npos) << field << "\n" << out;
  EXPECT_NE(status_line.find(" hal_backend=sim "), std::string::npos) << status_line;

  const Csv t = read_csv(csv_path);
  ASSERT_GT(t.rows, 6000u) << "3 s hold + 4 s sine at 1 kHz";
  expect_gapless(t, 0.001);
  expect_consistent_fields(t);
  const auto& time = t.col("t_s");
  const auto& r = t.col("r_um");
  const auto& e = t.col("e_um");
  const auto& chunk = t.col("chunk_seq");
  const auto& state = t.col("state");
  // Telemetry names the chunk in force: 0 before ours, then 1 (hold), then 2 (sine), never back.
  size_t first_hold = t.rows, first_sine = t.rows, last_hold = 0, last_sine = 0;
  for (size_t k = 0; k < t.rows; ++k) {
    if (k > 0) {
      ASSERT_GE(chunk[k], chunk[k - 1]) << "row " << k;
    }
    if (state[k] != 2.0) continue;  // RUNNING only: the ramp-down after stop is not the trajectory
    if (chunk[k] == 1.0) first_hold = std::min(first_hold, k), last_hold = k;
    if (chunk[k] == 2.0) first_sine = std::min(first_sine, k), last_sine = k;
  }
  ASSERT_LT(first_hold, t.rows) << "no telemetry row carries chunk_seq 1";
  ASSERT_LT(first_sine, t.rows) << "no telemetry row carries chunk_seq 2";
  ASSERT_EQ(last_hold + 1, first_sine);

  // Hold: after the blend (the daemon's soft start may stretch it) r is the level, y on it.
  double hold_r_dev = 0.0, hold_e = 0.0;
  for (size_t k = first_hold; k <= last_hold; ++k)
    if (time[k] > time[last_hold] - 0.8) {
      hold_r_dev = std::max(hold_r_dev, std::abs(r[k] - 60.0));
      hold_e = std::max(hold_e, std::abs(e[k]));
    }
  // Sine: r is the segment the client described, from the cycle that started it.
  const double t0 = time[first_sine];
  double sine_r_dev = 0.0, sine_e = 0.0, r_min = 1e9, r_max = -1e9;
  for (size_t k = first_sine; k <= last_sine; ++k) {
    sine_r_dev = std::max(sine_r_dev, std::abs(r[k] - (60.0 + 20.0 * std::sin(2.0 * M_PI * 0.5 * (time[k] - t0)))));
    r_min = std::min(r_min, r[k]);
    r_max = std::max(r_max, r[k]);
    if (time[k] > t0 + 0.5) sine_e = std::max(sine_e, std::abs(e[k]));
  }
  std::cout << "[interop] " << t.rows << " samples; hold (last 0.8 s): max |r - 60| " << hold_r_dev << " um, max |e| "
            << hold_e << " um; sine (" << (last_sine - first_sine + 1) << " cycles): max |r - formula| " << sine_r_dev
            << " um, r in [" << r_min << ", " << r_max << "], max |e| after 0.5 s " << sine_e << " um\n";
  EXPECT_LT(hold_r_dev, 1e-9);
  EXPECT_LT(hold_e, 1.0);
  EXPECT_LT(sine_r_dev, 1e-6);
  EXPECT_NEAR(r_min, 40.0, 0.01);
  EXPECT_NEAR(r_max, 80.0, 0.01);
  EXPECT_LT(sine_e, 2.0) << "the daemon e2e test's bound for a 0.5 Hz reference";
}

// The client refuses a Fast DDS profile that would leave loopback, before it
// creates a participant (so nothing is sent).
TEST(FastDdsInterop, ClientRefusesAProfileThatLeavesLoopback) {
  const std::string shipped = pvcgel::test::slurp(kFastDdsXml);
  struct Edit {
    const char* from;
    const char* to;
    const char* message;
  };
  for (const Edit& edit :
       {Edit{"<useBuiltinTransports>false</useBuiltinTransports>", "<useBuiltinTransports>true</useBuiltinTransports>",
             "useBuiltinTransports must be false"},
        Edit{"<metatrafficUnicastLocatorList>", "<metatrafficMulticastLocatorList><locator><udpv4><address>239.255.0.1"
                                                "</address></udpv4></locator></metatrafficMulticastLocatorList>"
                                                "<metatrafficUnicastLocatorList>",
             "discovery must be unicast"}}) {
    std::string xml = shipped;
    const auto pos = xml.find(edit.from);
    ASSERT_NE(pos, std::string::npos) << "the shipped profile no longer has " << edit.from;
    xml.replace(pos, std::strlen(edit.from), edit.to);
    const std::string path = temp_path("bad_profile.xml");
    std::ofstream(path) << xml;
    const auto r = pvcgel::test::run_program(
        kClient, {"--profile", path, "--domain", std::to_string(kDomain), "--wait", "1", "listen", "--out",
                  temp_path("never.csv")});
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_NE(r.err.find(edit.message), std::string::npos) << r.err;
  }
}

// --- this process as a Cyclone DDS peer -------------------------------------

using pvcgel::dds::Entity;

dds_qos_t* qos(bool transient_local, int depth) {
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(q, transient_local ? DDS_DURABILITY_TRANSIENT_LOCAL : DDS_DURABILITY_VOLATILE);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, depth);
  return q;
}

Entity make_endpoint(const Entity& participant, const dds_topic_descriptor_t* desc, const char* topic_name,
                     bool writer, bool transient_local, int depth) {
  const dds_entity_t topic = dds_create_topic(participant.get(), desc, topic_name, nullptr, nullptr);
  if (topic < 0) throw std::runtime_error(std::string("topic ") + topic_name);
  dds_qos_t* q = qos(transient_local, depth);
  const dds_entity_t e = writer ? dds_create_writer(participant.get(), topic, q, nullptr)
                                : dds_create_reader(participant.get(), topic, q, nullptr);
  dds_delete_qos(q);
  return Entity(e, topic_name);
}

/// Takes one sample from `reader` within `timeout_s`, as a copy made by `copy`.
template <class T, class Copy>
bool take_one(const Entity& reader, double timeout_s, Copy copy) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    void* samples[1] = {nullptr};
    dds_sample_info_t info;
    const int n = dds_take(reader.get(), samples, &info, 1, 1);
    if (n > 0) {
      const bool valid = info.valid_data;
      if (valid) copy(*static_cast<const T*>(samples[0]));
      dds_return_loan(reader.get(), samples, n);
      if (valid) return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

std::string exact(double x) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

TEST(FastDdsInterop, EveryTopicDecodesFieldByFieldBetweenCycloneAndFastDds) {
  pvcgel::dds::DdsSettings settings;
  settings.domain = kDomain;
  settings.config_path = kCycloneXml;
  const Entity participant = pvcgel::dds::make_participant(settings);
  const Entity trajectory_reader = make_endpoint(participant, &pvcgel_v1_Trajectory_desc, "pvcgel_v1_Trajectory", false, false, 64);
  const Entity command_reader = make_endpoint(participant, &pvcgel_v1_Command_desc, "pvcgel_v1_Command", false, false, 16);
  const Entity reply_writer = make_endpoint(participant, &pvcgel_v1_CommandReply_desc, "pvcgel_v1_CommandReply", true, false, 64);
  const Entity status_writer = make_endpoint(participant, &pvcgel_v1_Status_desc, "pvcgel_v1_Status", true, true, 1);

  // Status first: transient-local, so the Fast DDS reader gets it as a late joiner.
  pvcgel_v1_Status status{};
  std::snprintf(status.rig_id, sizeof status.rig_id, "interop_rig_b");
  status.t_s = 12.345678901234567;
  status.state = 2;
  status.fault = 9;
  status.mode = 3;
  status.target = 1;
  status.high_voltage = true;
  status.period_s = 0.001;
  status.queued_until_s = -1.5;
  status.cycles = 0x0123456789abcdefULL;
  status.overruns = 7;
  status.records_dropped = 1ULL << 40;
  status.latency_p50_us = 8.25f;
  status.latency_p99_us = 17.5f;
  status.latency_p999_us = 33.0f;
  status.latency_max_us = 101.125f;
  status.compute_p99_us = 3.0625f;
  status.chunks_accepted = 11;
  status.commands_accepted = 12;
  status.rejects_total = 13;
  for (uint32_t i = 0; i < 24; ++i) status.rejects_by_reason[i] = i * 1000003u;
  status.last_reject_reason = 23;
  std::snprintf(status.last_reject_detail, sizeof status.last_reject_detail, "%s", std::string(127, 'd').c_str());
  std::snprintf(status.config_hash, sizeof status.config_hash, "0123456789abcdef");
  std::snprintf(status.version, sizeof status.version, "0.1.0");
  std::snprintf(status.hal_backend, sizeof status.hal_backend, "sim");
  ASSERT_EQ(dds_write(status_writer.get(), &status), 0);

  const uint64_t seq = 41;
  const std::vector<double> values = {1.5, -2.25, 1e-300, 123456.789, -0.0, 7.0};
  std::string values_arg;
  for (double v : values) values_arg += (values_arg.empty() ? "" : ",") + exact(v);
  Process client(kClient,
               {"--profile", kFastDdsXml, "--domain", std::to_string(kDomain), "--rig", "interop_rig_b", "--client-id",
                "fastdds-echo", "--wait", "15", "echo", "--seq", std::to_string(seq), "--values", values_arg});

  // Fast DDS -> Cyclone: the Command and the Trajectory, every field.
  pvcgel_v1_Command command{};
  ASSERT_TRUE(take_one<pvcgel_v1_Command>(command_reader, 20.0, [&](const auto& c) { command = c; }))
      << client.err_so_far();
  EXPECT_STREQ(command.rig_id, "interop_rig_b");
  EXPECT_STREQ(command.client_id, "fastdds-echo");
  EXPECT_EQ(command.command_seq, seq + 1);
  EXPECT_EQ(command.kind, 7);
  EXPECT_EQ(command.argument, 255);
  bool got_trajectory = false;
  ASSERT_TRUE(take_one<pvcgel_v1_Trajectory>(trajectory_reader, 10.0, [&](const pvcgel_v1_Trajectory& t) {
    got_trajectory = true;
    EXPECT_STREQ(t.rig_id, "interop_rig_b");
    EXPECT_STREQ(t.client_id, "fastdds-echo");
    EXPECT_EQ(t.chunk_seq, seq);
    EXPECT_EQ(t.publish_time_ns, -static_cast<int64_t>(seq));
    EXPECT_EQ(t.target, 1);
    EXPECT_EQ(t.kind, 0);
    EXPECT_EQ(t.timing, 1);
    EXPECT_EQ(t.start_time_s, 41.5);
    EXPECT_EQ(t.period_s, 0.002);
    EXPECT_EQ(t.duration_s, 0.25);
    EXPECT_EQ(t.blend_s, 0.125);
    ASSERT_EQ(t.values._length, values.size());
    for (size_t i = 0; i < values.size(); ++i) EXPECT_EQ(std::memcmp(&t.values._buffer[i], &values[i], 8), 0) << i;
  })) << client.err_so_far();
  EXPECT_TRUE(got_trajectory);

  // Cyclone -> Fast DDS: a CommandReply once the client's reader is there (volatile).
  dds_publication_matched_status_t matched{};
  for (int i = 0; i < 1000 && matched.current_count == 0; ++i) {
    dds_get_publication_matched_status(reply_writer.get(), &matched);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_GT(matched.current_count, 0u) << client.err_so_far();
  pvcgel_v1_CommandReply reply{};
  std::snprintf(reply.rig_id, sizeof reply.rig_id, "interop_rig_b");
  std::snprintf(reply.client_id, sizeof reply.client_id, "fastdds-echo");
  reply.seq = seq;
  reply.is_trajectory = true;
  reply.accepted = false;
  reply.reason = 5;
  std::snprintf(reply.detail, sizeof reply.detail, "values[2] = 1e-300: some reason with spaces");
  ASSERT_EQ(dds_write(reply_writer.get(), &reply), 0);

  const auto client_result = client.wait();
  ASSERT_EQ(client_result.exit_code, 0) << client_result.err;
  const std::string& out = client_result.out;
  EXPECT_NE(out.find("reply rig_id=interop_rig_b client_id=fastdds-echo seq=41 is_trajectory=1 accepted=0 reason=5 "
                     "detail=values[2] = 1e-300: some reason with spaces\n"),
            std::string::npos)
      << out;
  std::string rejects;
  for (uint32_t i = 0; i < 24; ++i) rejects += (i ? "," : "") + std::to_string(i * 1000003u);
  const std::string expected_status =
      "status rig_id=interop_rig_b t_s=12.345678901234567 state=2 fault=9 mode=3 target=1 high_voltage=1 "
      "period_s=0.001 queued_until_s=-1.5 cycles=" + std::to_string(0x0123456789abcdefULL) +
      " overruns=7 records_dropped=" + std::to_string(1ULL << 40) +
      " latency_p50_us=8.25 latency_p99_us=17.5 latency_p999_us=33 latency_max_us=101.125 compute_p99_us=3.0625"
      " chunks_accepted=11 commands_accepted=12 rejects_total=13 rejects_by_reason=" + rejects +
      " last_reject_reason=23 last_reject_detail=" + std::string(127, 'd') +
      " config_hash=0123456789abcdef version=0.1.0 hal_backend=sim\n";
  EXPECT_NE(out.find(expected_status), std::string::npos) << "expected:\n" << expected_status << "got:\n" << out;
}

}  // namespace
