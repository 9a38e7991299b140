// End to end over DDS on loopback: the real pvcgeld (sim backend) driven by
// the real `pvcgel` client binary and by the client library.
#include <gtest/gtest.h>

#include <algorithm>
#include <deque>
#include <filesystem>
#include <cmath>
#include <fstream>
#include <regex>
#include <thread>

#include "support/subprocess.hpp"
#include "daemon/dds/dds_messages.hpp"
#include "tools/dds_client.hpp"
#include "tools/recording.hpp"

using namespace pvcgel;
using test::Process;
using test::Result;
using test::run_program;

namespace {

const std::string kDaemon = PVCGELD_PATH;
const std::string kClient = PVCGEL_PATH;
const std::string kDdsConfig = std::string(PVCGEL_SOURCE_DIR) + "/config/cyclonedds-loopback.xml";
const std::string kSimConfig = std::string(PVCGEL_SOURCE_DIR) + "/config/pvcgeld-sim.toml";
/// This process's DDS domain (each test runs in its own process under ctest).
const int kDomain = test::unique_dds_domain();

/// A daemon config: the shipped sim config, idle at start, on `domain` as `rig`.
std::string write_config(const std::string& name, int domain, const std::string& rig, const std::string& extra = "",
                         const std::string& dds_xml = kDdsConfig) {
  std::string text = test::slurp(kSimConfig);
  text = std::regex_replace(text, std::regex("\ntrajectory = [^\n]*"), "\n");
  text = std::regex_replace(text, std::regex("\ndomain = 0"), "\ndomain = " + std::to_string(domain));
  text = std::regex_replace(text, std::regex("\nrig_id = \"rig1\""), "\nrig_id = \"" + rig + "\"");
  text = std::regex_replace(text, std::regex("config = \"cyclonedds-loopback.xml\""), "config = \"" + dds_xml + "\"");
  text += extra;
  const std::string path = ::testing::TempDir() + name + ".toml";
  std::ofstream(path) << text;
  return path;
}

std::vector<std::string> client_args(std::vector<std::string> args, int domain, const std::string& rig) {
  args.insert(args.end(), {"--rig", rig, "--domain", std::to_string(domain), "--dds-config", kDdsConfig, "--wait", "10"});
  return args;
}

Result client(std::vector<std::string> args, int domain, const std::string& rig) {
  return run_program(kClient, client_args(std::move(args), domain, rig));
}

tools::ClientOptions options(int domain, const std::string& rig) {
  tools::ClientOptions o;
  o.rig = rig;
  o.domain = domain;
  o.dds_config = kDdsConfig;
  o.wait_s = 10.0;
  return o;
}

}  // namespace

// The paper's four references, each a one-line `pvcgel send`, recorded
// losslessly with `pvcgel record`; tracking as in the daemon issue's figures.
TEST(DdsE2E, EachPaperReferenceIsSentRecordedAndTracked) {
  Process daemon(kDaemon, {"--config", write_config("paper", kDomain, "paper")});
  ASSERT_EQ(client({"start"}, kDomain, "paper").exit_code, 0);
  struct Ref {
    const char* name;
    double bench_mean_um;  // `pvcgel bench paper`, inverse_pid_dob, mean |e|
    double span_um;        // peak-to-peak of r within the 5 s window, at least
  };
  for (const Ref ref : {Ref{"0.1Hz", 0.076, 20.0}, Ref{"0.5Hz", 0.435, 45.0}, Ref{"1Hz", 0.886, 45.0}, Ref{"multi", 0.435, 30.0}}) {
    SCOPED_TRACE(ref.name);
    const auto sent = client({"send", "paper", ref.name, "--blend", "1"}, kDomain, "paper");
    ASSERT_EQ(sent.exit_code, 0) << sent.err;
    std::this_thread::sleep_for(std::chrono::seconds(2));  // blend and settle
    const std::string out = ::testing::TempDir() + "dds_paper_" + ref.name + ".csv";
    const auto rec_run = client({"record", "--out", out, "--duration", "5"}, kDomain, "paper");
    ASSERT_EQ(rec_run.exit_code, 0) << rec_run.err;  // exit 5 would mean sequence gaps
    const auto rec = tools::read_recording(out);
    EXPECT_GE(rec.rows(), 5000u);
    EXPECT_EQ(rec.skipped_rows, 0);
    const auto& e = rec.col("e_um");
    const auto& r = rec.col("r_um");
    double sum = 0;
    for (double x : e) sum += std::abs(x);
    const double mean = sum / static_cast<double>(e.size());
    const auto [lo, hi] = std::minmax_element(r.begin(), r.end());
    std::cout << "[dds] " << ref.name << ": mean |e| " << mean << " um (bench " << ref.bench_mean_um << "), r span "
              << *hi - *lo << " um\n";
    EXPECT_LT(mean, 1.5 * ref.bench_mean_um + 0.05);
    EXPECT_GT(*hi - *lo, ref.span_um);
    EXPECT_EQ(rec.text.at("state").back(), "RUNNING");
  }
  const auto r = daemon.stop();
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

// Several rigs on one domain, told apart by the rig id key.
TEST(DdsE2E, TwoDaemonsOnOneDomainOnlyTheAddressedRigActs) {
  Process left(kDaemon, {"--config", write_config("left", kDomain, "left")});
  Process right(kDaemon, {"--config", write_config("right", kDomain, "right")});
  ASSERT_EQ(client({"start"}, kDomain, "left").exit_code, 0);
  const auto sent = client({"send", "hold", "20", "--blend", "1"}, kDomain, "left");
  ASSERT_EQ(sent.exit_code, 0) << sent.err;
  tools::DdsClient l(options(kDomain, "left")), r(options(kDomain, "right"));
  l.connect();
  r.connect();
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  const auto ls = l.status(), rs = r.status();
  EXPECT_EQ(ls.state, 2) << "left RUNNING";
  EXPECT_EQ(rs.state, 0) << "right still DISABLED";
  EXPECT_EQ(ls.chunks_accepted, 1u);
  EXPECT_EQ(rs.chunks_accepted, 0u);
  EXPECT_EQ(rs.commands_accepted, 0u);
  const auto unknown = run_program(kClient, {"status", "--rig", "middle", "--domain", std::to_string(kDomain), "--dds-config", kDdsConfig, "--wait", "2"});
  EXPECT_EQ(unknown.exit_code, 3);
  EXPECT_NE(unknown.err.find("rig 'middle' unknown; rigs seen:"), std::string::npos) << unknown.err;
  EXPECT_EQ(left.stop().exit_code, 0);
  EXPECT_EQ(right.stop().exit_code, 0);
}

// Every validation rule, over DDS: refused with the right reason and counted,
// while the loop keeps running.
TEST(DdsE2E, EveryBadInputIsRejectedWithItsReasonAndTheLoopKeepsRunning) {
  std::string cfg = test::slurp(write_config("validate", kDomain, "val"));
  cfg = std::regex_replace(cfg, std::regex("\nmax_chunk_samples = 1024"), "\nmax_chunk_samples = 256");
  ASSERT_NE(cfg.find("max_chunk_samples = 256"), std::string::npos);
  const std::string cfg_path = ::testing::TempDir() + "validate_256.toml";
  std::ofstream(cfg_path) << cfg;
  Process daemon(kDaemon, {"--config", cfg_path});
  tools::DdsClient c(options(kDomain, "val"));
  c.connect();
  c.command(daemon::CommandKind::arm);
  c.command(daemon::CommandKind::start);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const double now = c.status().t_s;
  const auto overruns_before = c.status().overruns;

  std::deque<std::vector<double>> store;  // the samples' buffers, alive until sent
  auto traj = [&](std::uint8_t kind, std::vector<double> v) {
    const auto& values = store.emplace_back(std::move(v));
    pvcgel_v1_Trajectory t{};
    t.kind = kind;
    t.period_s = 1e-3;
    t.start_time_s = -1;
    t.blend_s = 1.0;
    t.values._buffer = const_cast<double*>(values.data());
    t.values._length = t.values._maximum = static_cast<uint32_t>(values.size());
    return t;
  };
  using R = daemon::RejectReason;
  struct Case {
    const char* what;
    pvcgel_v1_Trajectory t;
    R reason;
  };
  std::vector<Case> cases;
  cases.push_back({"NaN", traj(1, {NAN}), R::not_finite});
  cases.push_back({"out of range", traj(1, {500}), R::out_of_range});
  cases.push_back({"step between samples", traj(0, {10, 10, 30}), R::step_too_large});
  cases.push_back({"slope", traj(3, {100, 25, 8.0, 0}), R::slope_too_large});
  auto past = traj(1, {10});
  past.start_time_s = std::max(0.0, now - 1.0);
  cases.push_back({"in the past", past, R::in_the_past});
  auto ahead = traj(1, {10});
  ahead.start_time_s = now + 100.0;
  cases.push_back({"too far ahead", ahead, R::too_far_ahead});
  cases.push_back({"chunk too large", traj(0, std::vector<double>(300, 10.0)), R::chunk_too_large});
  auto period = traj(0, {10, 10});
  period.period_s = 1e-5;
  cases.push_back({"period", period, R::bad_period});
  auto volts = traj(1, {300});
  volts.target = 1;
  cases.push_back({"target", volts, R::target_mismatch});
  auto jump = traj(1, {150});
  jump.blend_s = 0.0;
  cases.push_back({"step from the setpoint in force (the loop's check)", jump, R::step_too_large});
  for (auto& k : cases) {
    SCOPED_TRACE(k.what);
    const auto reply = c.send(k.t, false);
    EXPECT_FALSE(reply.accepted);
    EXPECT_EQ(reply.reason, k.reason) << reply.detail;
    EXPECT_FALSE(reply.detail.empty());
  }
  const auto illegal = c.command(daemon::CommandKind::reset, 0, false);
  EXPECT_EQ(illegal.reason, R::illegal_in_state) << illegal.detail;
  const auto unknown = c.command(static_cast<daemon::CommandKind>(42), 0, false);
  EXPECT_EQ(unknown.reason, R::unknown_command);
  const auto mode = c.command(daemon::CommandKind::set_mode, 9, false);
  EXPECT_EQ(mode.reason, R::bad_argument);
  auto fine = traj(1, {12.0});
  const auto good = c.send(fine, false);
  EXPECT_TRUE(good.accepted) << good.detail;

  std::this_thread::sleep_for(std::chrono::milliseconds(600));
  const auto s = c.status();
  EXPECT_EQ(s.state, 2) << "still RUNNING";
  EXPECT_EQ(s.fault, 0);
  EXPECT_EQ(s.rejects_total, cases.size() + 3);
  EXPECT_EQ(s.rejects_by_reason[static_cast<int>(R::step_too_large)], 2u);
  EXPECT_EQ(s.rejects_by_reason[static_cast<int>(R::not_finite)], 1u);
  std::cout << "[dds] overruns during the bad inputs: " << s.overruns - overruns_before << "\n";
  EXPECT_EQ(daemon.stop().exit_code, 0);
}

// Open-loop voltage mode for identification: voltage setpoints reach the
// amplifier, clamped and slew-limited.
TEST(DdsE2E, OpenLoopVoltageModeDrivesTheAmplifier) {
  Process daemon(kDaemon, {"--config", write_config("volts", kDomain, "volts")});
  ASSERT_EQ(client({"target", "voltage"}, kDomain, "volts").exit_code, 0);
  ASSERT_EQ(client({"start"}, kDomain, "volts").exit_code, 0);
  const auto sent = client({"send", "sine", "450", "300", "1", "--voltage", "--blend", "0.5"}, kDomain, "volts");
  ASSERT_EQ(sent.exit_code, 0) << sent.err;
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const std::string out = ::testing::TempDir() + "dds_volts.csv";
  ASSERT_EQ(client({"record", "--out", out, "--duration", "2"}, kDomain, "volts").exit_code, 0);
  const auto rec = tools::read_recording(out);
  const auto& u = rec.col("u_V");
  const auto [lo, hi] = std::minmax_element(u.begin(), u.end());
  EXPECT_NEAR(*lo, 150.0, 2.0);
  EXPECT_NEAR(*hi, 750.0, 2.0);
  const auto running = client({"target", "displacement"}, kDomain, "volts");
  EXPECT_EQ(running.exit_code, 4) << "not while RUNNING";
  EXPECT_NE(running.err.find("illegal_in_state"), std::string::npos) << running.err;
  EXPECT_EQ(daemon.stop().exit_code, 0);
}

// A participant that claims to be a daemon but publishes a state and a fault no
// pvcgel knows (a newer daemon, or a corrupt one): the client names the field
// and the value and fails (exit 1), instead of indexing a name table with them.
TEST(DdsE2E, AStatusWithAnUnknownStateIsReportedClearlyByTheClient) {
  dds::DdsSettings s;
  s.domain = kDomain;
  s.config_path = kDdsConfig;
  s.rig_id = "alien";
  const auto participant = dds::make_participant(s);
  const auto status_topic = dds::make_topic(participant.get(), dds::Topic::status);
  const auto reply_topic = dds::make_topic(participant.get(), dds::Topic::command_reply);
  const dds::Entity status_writer(dds_create_writer(participant.get(), status_topic.get(), dds::status_qos().get(), nullptr),
                                  "Status writer");
  // The client waits for the daemon's reply writer to match before it trusts the Status.
  const dds::Entity reply_writer(dds_create_writer(participant.get(), reply_topic.get(), dds::reply_qos().get(), nullptr),
                                 "CommandReply writer");
  pvcgel_v1_Status st{};
  dds::copy_bounded(st.rig_id, "alien");
  st.state = 200;
  st.fault = 77;
  st.period_s = 1e-3;
  ASSERT_EQ(dds_write(status_writer.get(), &st), DDS_RETCODE_OK);
  const auto r = client({"status"}, kDomain, "alien");
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.err.find("Status.state = 200 is not a value this program knows (0 DISABLED, 1 ARMED, 2 RUNNING"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(r.out.find("rig alien:"), std::string::npos) << "nothing printed from a Status it cannot read: " << r.out;
}

// A client publishing far faster than allowed for 10 s is throttled with
// reasons; the loop keeps running and its timing is compared (printed) before
// and during the flood.
TEST(DdsE2E, AFloodOfChunksAndCommandsIsThrottledAndTheLoopKeepsItsTiming) {
  Process daemon(kDaemon, {"--config", write_config("flood", kDomain, "flood")});
  tools::DdsClient c(options(kDomain, "flood"));
  c.connect();
  c.command(daemon::CommandKind::arm);
  c.command(daemon::CommandKind::start);
  const std::string out = ::testing::TempDir() + "dds_flood.csv";
  Process recorder(kClient, client_args({"record", "--out", out, "--duration", "15"}, kDomain, "flood"));
  std::this_thread::sleep_for(std::chrono::seconds(4));  // baseline
  const double flood_start = c.status().t_s;
  std::vector<double> level{10.0};
  pvcgel_v1_Trajectory t{};
  t.kind = 1;
  t.start_time_s = -1;
  t.blend_s = 0.5;
  t.values._buffer = level.data();
  t.values._length = t.values._maximum = 1;
  std::uint64_t published = 0, rate_limited_replies = 0;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (std::chrono::steady_clock::now() < end) {
    level[0] = 10.0 + static_cast<double>(published % 2);
    c.publish_trajectory(t);
    c.publish_command(daemon::CommandKind::set_mode, 2);
    published += 2;
    if (published % 64 == 0)
      for (const auto& r : c.take_replies()) rate_limited_replies += r.reason == static_cast<uint8_t>(daemon::RejectReason::rate_limited);
  }
  const double flood_end = c.status().t_s;
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  for (const auto& r : c.take_replies()) rate_limited_replies += r.reason == static_cast<uint8_t>(daemon::RejectReason::rate_limited);
  const auto s = c.status();
  const auto rec_result = recorder.wait();
  EXPECT_EQ(rec_result.exit_code, 0) << "telemetry kept flowing without gaps: " << rec_result.err;

  const auto limit = daemon::SetpointLimits{};
  std::cout << "[flood] published " << published << " messages in 10 s; accepted " << s.chunks_accepted << " chunks, "
            << s.commands_accepted << " commands; rate_limited " << s.rejects_by_reason[static_cast<int>(daemon::RejectReason::rate_limited)]
            << " (replies seen " << rate_limited_replies << ")\n";
  EXPECT_GT(published, 5000u) << "not a flood";
  EXPECT_GT(s.rejects_by_reason[static_cast<int>(daemon::RejectReason::rate_limited)], 1000u);
  EXPECT_GT(rate_limited_replies, 10u) << "the flooding client is told why";
  // Token buckets: at most rate x time + burst get through (plus the two start commands).
  EXPECT_LE(s.chunks_accepted, limit.max_chunks_per_s * 10.5 + limit.max_chunks_per_s * limit.burst_s + 1);
  EXPECT_LE(s.commands_accepted, limit.max_commands_per_s * 10.5 + limit.max_commands_per_s * limit.burst_s + 3);
  EXPECT_EQ(s.state, 2) << "still RUNNING";
  EXPECT_EQ(s.fault, 0);

  // Wake-up latency per cycle from the recording: before vs during the flood.
  const auto rec = tools::read_recording(out);
  std::vector<double> before, during;
  const auto& ts = rec.col("t_s");
  const auto& lat = rec.col("latency_us");
  for (std::size_t k = 0; k < ts.size(); ++k) {
    if (ts[k] < flood_start) before.push_back(lat[k]);
    else if (ts[k] < flood_end) during.push_back(lat[k]);
  }
  ASSERT_GT(before.size(), 1000u);
  ASSERT_GT(during.size(), 5000u);
  const auto p999 = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(0.999 * static_cast<double>(v.size() - 1))];
  };
  const double b = p999(before), d = p999(during);
  // Printed, not asserted: this shared CI machine's jitter is noise (see the benchmark for the comparison).
  std::cout << "[flood] wake-up latency p99.9: before " << b << " us, during " << d << " us, ratio " << d / b << "\n";
  EXPECT_EQ(daemon.stop().exit_code, 0);
}

// DDS Security with test certificates (config/dds-security/make-test-pki.sh):
// an authenticated client drives the rig, a read-only identity may watch but
// not command, and a participant without credentials does not even see it.
TEST(DdsE2E, SecuredModeAuthenticatesAndEnforcesPermissions) {
  if (std::system("command -v openssl > /dev/null") != 0) GTEST_SKIP() << "skipped: openssl not installed";
  if (std::system("test -e /usr/lib/x86_64-linux-gnu/libddsc0debian/libdds_security_auth.so") != 0)
    GTEST_SKIP() << "skipped: Cyclone DDS Security plugins not installed";
  const std::string pki = ::testing::TempDir() + "pvcgel_pki_" + std::to_string(getpid());
  ASSERT_EQ(std::system(("rm -rf " + pki + " && " + PVCGEL_SOURCE_DIR + "/config/dds-security/make-test-pki.sh " + pki + " " +
                         std::to_string(kDomain) + " > /dev/null")
                            .c_str()),
            0);
  Process daemon(kDaemon, {"--config", write_config("secure", kDomain, "sec", "", pki + "/daemon.xml")});
  const auto with = [&](const std::string& xml, std::vector<std::string> args, const char* wait = "10") {
    args.insert(args.end(), {"--rig", "sec", "--domain", std::to_string(kDomain), "--dds-config", xml, "--wait", wait});
    return run_program(kClient, args);
  };
  const auto started = with(pki + "/client.xml", {"start"});
  EXPECT_EQ(started.exit_code, 0) << started.err;
  const auto sent = with(pki + "/client.xml", {"send", "hold", "15", "--blend", "1"});
  EXPECT_EQ(sent.exit_code, 0) << sent.err;
  const auto observed = with(pki + "/observer.xml", {"status"});
  EXPECT_EQ(observed.exit_code, 0) << observed.err;
  EXPECT_NE(observed.out.find("RUNNING"), std::string::npos) << observed.out;
  EXPECT_NE(observed.out.find("1 chunks"), std::string::npos) << observed.out;
  const auto refused = with(pki + "/observer.xml", {"stop"});
  EXPECT_NE(refused.exit_code, 0);
  EXPECT_NE(refused.err.find("Not Allowed By Security"), std::string::npos) << refused.err;
  const auto plain = with(kDdsConfig, {"status"}, "3");
  EXPECT_EQ(plain.exit_code, 3) << "an unauthenticated participant does not see the rig: " << plain.err;
  EXPECT_EQ(daemon.stop().exit_code, 0);
}

// `pvcgel ident --rig`: the excitation plan runs on the daemon in open-loop
// voltage mode over DDS; the recordings are kept and the fitted model is one
// the daemon accepts. (A short plan: one amplitude and bias, four frequencies.)
TEST(DdsE2E, IdentificationOnARunningRigOverDds) {
  Process daemon(kDaemon, {"--config", write_config("ident", kDomain, "ident")});
  const std::string dir = ::testing::TempDir() + "ident_rig_recordings";
  const std::string model = ::testing::TempDir() + "ident_rig_model.toml";
  std::filesystem::remove_all(dir);
  const auto r = run_program(kClient, {"ident", "--rig", "ident", "--domain", std::to_string(kDomain), "--dds-config", kDdsConfig,
                                       "--amplitudes", "300", "--biases", "450", "--freq-min", "0.3", "--freq-max", "5",
                                       "--freq-count", "4", "--plan-settle", "1.5", "--min-analysed", "2",
                                       "--validation-freqs", "2", "--save-recordings", dir, "--out", model});
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  EXPECT_NE(r.err.find("[5/5] A = 400 V, B = 450 V, f = 2.000 Hz"), std::string::npos) << r.err;
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() != ".csv") continue;
    ++files;
    const auto rec = tools::read_recording(e.path().string());  // uniform time: no lost cycles
    EXPECT_EQ(rec.skipped_rows, 0);
  }
  EXPECT_EQ(files, 4);
  // The fitted G against the truth of the simulated rig (eq. 11: poles -0.547, -16.56; zero -0.896).
  const std::regex pole_line(R"(poles: (-[\d.]+), (-[\d.]+))");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.out, m, pole_line)) << r.out;
  const double p1 = std::stod(m[1]), p2 = std::stod(m[2]);
  std::cout << "[ident --rig] poles " << p1 << ", " << p2 << "\n";
  EXPECT_NEAR(std::max(p1, p2), -0.547, 0.547 * 0.25) << "slow pole (short plan, creep not settled)";
  EXPECT_NEAR(std::min(p1, p2), -16.56, 16.56 * 0.1);
  // The daemon takes the written [model] as it is.
  std::string cfg = test::slurp(write_config("ident_model", kDomain, "ident"));
  const std::string model_text = test::slurp(model);
  // Its [model] table replaces the config's, and a voltage limit it carries (f
  // turning over below 1000 V) replaces the config's controller.voltage_max_V.
  std::smatch table;
  ASSERT_TRUE(std::regex_search(model_text, table, std::regex(R"(\[model\][\s\S]*?(?=\n\[|$))"))) << model_text;
  cfg = std::regex_replace(cfg, std::regex(R"(\[model\][\s\S]*?\n\[controller\])"), table.str() + "\n\n[controller]");
  std::smatch limit;
  if (std::regex_search(model_text, limit, std::regex(R"(\nvoltage_max_V = ([\d.]+))")))
    cfg = std::regex_replace(cfg, std::regex(R"(\nvoltage_max_V = [\d.]+)"), "\nvoltage_max_V = " + limit[1].str());
  const std::string cfg_path = ::testing::TempDir() + "ident_model_daemon.toml";
  std::ofstream(cfg_path) << cfg;
  const auto check = run_program(kDaemon, {"--config", cfg_path, "--check-config"});
  EXPECT_EQ(check.exit_code, 0) << check.err << check.out;
  // The rig is left safe: DISABLED, displacement setpoints.
  tools::DdsClient c(options(kDomain, "ident"));
  const auto s = c.fresh_status();
  EXPECT_EQ(s.state, 0);
  EXPECT_EQ(s.target, 0);
  EXPECT_EQ(daemon.stop().exit_code, 0);
}

// A client resends a command that got no reply (the daemon's reader may not
// have matched its writer yet); the daemon applies it once and answers again.
TEST(DdsE2E, AResentCommandIsAppliedOnceAndAnsweredAgain) {
  Process daemon(kDaemon, {"--config", write_config("resend", kDomain, "resend")});
  tools::DdsClient c(options(kDomain, "resend"));
  c.connect();
  const auto seq = c.publish_command(daemon::CommandKind::arm, 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  c.publish_command(daemon::CommandKind::arm, 0, seq);  // the same command again
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  int answers = 0;
  for (const auto& r : c.take_replies()) {
    if (r.seq != seq) continue;
    ++answers;
    EXPECT_TRUE(r.accepted) << "answered with the first outcome, not 'illegal_in_state': " << r.detail;
  }
  EXPECT_EQ(answers, 2);
  const auto s = c.fresh_status();
  EXPECT_EQ(s.commands_accepted, 1u);
  EXPECT_EQ(s.rejects_total, 0u);
  EXPECT_EQ(s.state, 1) << "ARMED once";
  EXPECT_EQ(daemon.stop().exit_code, 0);
}
