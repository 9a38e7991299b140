// End to end: the real pvcgeld binary, sim backend, as a subprocess.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "support/subprocess.hpp"
#include "tools/recording.hpp"

namespace {

const std::string kDaemon = PVCGELD_PATH;
const std::string kClient = PVCGEL_PATH;
const std::string kDdsConfig = std::string(PVCGEL_SOURCE_DIR) + "/config/cyclonedds-loopback.xml";
/// The shipped sim config, publishing on this process's own DDS domain.
const int kDomain = pvcgel::test::unique_dds_domain();
const std::string kSimConfig = pvcgel::test::sim_config_on_domain(PVCGEL_SOURCE_DIR, kDomain, "e2e_sim");
const std::string kDomainArg = std::to_string(kDomain);

using pvcgel::test::Result;
using pvcgel::test::run_program;
using pvcgel::test::slurp;

Result run_daemon(std::vector<std::string> args, double sigterm_after_s = 0.0) {
  return run_program(kDaemon, std::move(args), sigterm_after_s);
}

size_t first_index_of(const std::vector<std::string>& v, const std::string& s) {
  for (size_t i = 0; i < v.size(); ++i)
    if (v[i] == s) return i;
  return v.size();
}

TEST(PvcgeldE2E, PaperReferenceThenSigtermRampsDownAndRecordsEverything) {
  const std::string rec_path = ::testing::TempDir() + "e2e_sigterm.csv";
  const auto r = run_daemon({"--config", kSimConfig, "--trajectory", "paper-1hz", "--record", rec_path}, 5.0);
  ASSERT_EQ(r.signal, 0) << r.err;
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("SIGTERM"), std::string::npos);
  EXPECT_NE(r.err.find("sequence gaps 0"), std::string::npos) << r.err;

  const auto rec = pvcgel::tools::read_recording(rec_path);  // throws on non-uniform time = missing rows
  EXPECT_EQ(rec.skipped_rows, 0);
  EXPECT_GT(rec.rows(), 4000u);
  EXPECT_EQ(rec.header.at("rate_hz"), "1000");
  const auto& state = rec.text.at("state");
  const auto& u = rec.col("u_V");
  const size_t ramp = first_index_of(state, "RAMP_DOWN");
  ASSERT_LT(ramp, state.size()) << "the ramp-down must be in the recording";
  for (size_t k = ramp + 1; k < u.size(); ++k) ASSERT_LE(u[k], u[k - 1] + 1e-9) << "output must only fall after stop";
  EXPECT_EQ(u.back(), 0.0);
  EXPECT_EQ(state.back(), "DISABLED");
  EXPECT_EQ(rec.col("hv").back(), 0.0);
  // The ramp takes u / rate: 500 V/s in the sim config.
  const double ramp_s = rec.col("t_s").back() - rec.col("t_s")[ramp];
  EXPECT_LE(ramp_s, u[ramp - 1] / 500.0 + 0.01);
}

TEST(PvcgeldE2E, DurationRunExitsCleanlyWithTrackingError) {
  const std::string rec_path = ::testing::TempDir() + "e2e_duration.csv";
  const auto r = run_daemon({"--config", kSimConfig, "--trajectory", "paper-0.5hz", "--duration", "4", "--record", rec_path});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const auto rec = pvcgel::tools::read_recording(rec_path);
  const auto& state = rec.text.at("state");
  const auto& e = rec.col("e_um");
  double worst = 0.0;
  long running = 0;
  for (size_t k = 0; k < e.size(); ++k)
    if (state[k] == "RUNNING" && rec.col("t_s")[k] > 4.0) {
      worst = std::max(worst, std::abs(e[k]));
      ++running;
    }
  EXPECT_GT(running, 1500);
  // Bench: inverse_pid_dob at 0.5 Hz has max |e| 0.86 um; allow start-up residue.
  EXPECT_LT(worst, 2.0);

  // The quick start's second half: `show --plot` writes the PNG and nothing else beside it.
  const std::filesystem::path dir = ::testing::TempDir() + "e2e_show_plot";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const auto show = run_program(kClient, {"show", rec_path, "--plot", (dir / "duration.png").string()});
  ASSERT_EQ(show.exit_code, 0) << show.err << show.out;
  std::vector<std::string> files;
  for (const auto& f : std::filesystem::directory_iterator(dir)) files.push_back(f.path().filename().string());
  EXPECT_EQ(files, std::vector<std::string>{"duration.png"});
  EXPECT_GT(std::filesystem::file_size(dir / "duration.png"), 10000u);
}

// Telemetry over DDS (loopback-only Cyclone configuration): a late-joining
// reliable reader records every cycle from where it joined, without gaps.
TEST(PvcgelRecordE2E, LosslessTelemetryRecordingOverDds) {
  const std::string out = ::testing::TempDir() + "e2e_dds_record.csv";
  std::thread daemon([] {
    const auto r = run_daemon({"--config", kSimConfig, "--trajectory", "paper-0.5hz", "--duration", "5"});
    EXPECT_EQ(r.exit_code, 0) << r.err;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const auto r = run_program(kClient, {"record", "--out", out, "--duration", "3", "--dds-config", kDdsConfig, "--domain", kDomainArg, "--wait", "10"});
  daemon.join();
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("sequence gaps 0"), std::string::npos) << r.err;
  const auto rec = pvcgel::tools::read_recording(out);  // throws on missing rows (non-uniform time)
  EXPECT_GE(rec.rows(), 3000u);
  EXPECT_EQ(rec.header.at("rig_id"), "rig1");
}

TEST(PvcgelRecordE2E, UnknownRigAndNoDaemonAreReported) {
  std::thread daemon([] { (void)run_daemon({"--config", kSimConfig, "--trajectory", "hold:50", "--duration", "3"}); });
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const auto wrong = run_program(kClient, {"record", "--out", ::testing::TempDir() + "x.csv", "--rig", "rig9",
                                           "--dds-config", kDdsConfig, "--domain", kDomainArg, "--wait", "2"});
  daemon.join();
  EXPECT_NE(wrong.exit_code, 0);
  EXPECT_NE(wrong.err.find("rig 'rig9' unknown; rigs seen: rig1"), std::string::npos) << wrong.err;
  const auto none = run_program(kClient, {"record", "--out", ::testing::TempDir() + "y.csv", "--dds-config", kDdsConfig, "--domain", kDomainArg,
                                          "--wait", "1"});
  EXPECT_NE(none.exit_code, 0);
  EXPECT_NE(none.err.find("no daemon found within"), std::string::npos) << none.err;
}

TEST(PvcgelRecordE2E, StreamThatStopsEndsTheRecordingWithAnError) {
  const std::string out = ::testing::TempDir() + "e2e_dds_stopped.csv";
  std::thread daemon([] { (void)run_daemon({"--config", kSimConfig, "--trajectory", "hold:50", "--duration", "1"}); });
  const auto r = run_program(kClient, {"record", "--out", out, "--duration", "30", "--dds-config", kDdsConfig, "--domain", kDomainArg, "--wait", "2"});
  daemon.join();
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("telemetry stopped"), std::string::npos) << r.err;
  EXPECT_GT(pvcgel::tools::read_recording(out).rows(), 500u) << "what arrived is kept";
}

struct E2EFault {
  const char* inject;
  const char* reason;
};
void PrintTo(const E2EFault& f, std::ostream* os) { *os << f.inject; }
class PvcgeldFault : public ::testing::TestWithParam<E2EFault> {};

TEST_P(PvcgeldFault, RightReasonZeroVoltsHighVoltageOffNoCrash) {
  const std::string rec_path = ::testing::TempDir() + std::string("e2e_fault_") + GetParam().inject + ".csv";
  const auto r = run_daemon({"--config", kSimConfig, "--trajectory", "paper-1hz", "--duration", "20", "--record",
                             rec_path, "--inject-fault", std::string(GetParam().inject) + "@3"});
  ASSERT_EQ(r.signal, 0) << "crashed: " << r.err;
  EXPECT_EQ(r.exit_code, 3) << "a run that ends in FAULT exits 3: " << r.err;
  EXPECT_NE(r.err.find(std::string("fault: ") + GetParam().reason), std::string::npos) << r.err;
  // Keep the rows where the faulted sensor was recorded as NaN.
  const auto rec = pvcgel::tools::read_recording(rec_path, true);
  const auto& fault = rec.text.at("fault");
  const auto& u = rec.col("u_V");
  const auto& t = rec.col("t_s");
  const size_t first = first_index_of(fault, GetParam().reason);
  ASSERT_LT(first, fault.size()) << "reason code missing from the recording";
  size_t zero = first;
  while (zero < u.size() && u[zero] > 0.0) ++zero;
  ASSERT_LT(zero, u.size());
  EXPECT_LE(t[zero] - t[first], u[first - 1] / 500.0 + 0.01) << "0 V within the configured ramp time";
  EXPECT_EQ(rec.text.at("state").back(), "FAULT");
  EXPECT_EQ(rec.col("hv").back(), 0.0);
  EXPECT_EQ(u.back(), 0.0);
}

INSTANTIATE_TEST_SUITE_P(EveryInjectedFault, PvcgeldFault,
                         ::testing::Values(E2EFault{"sensor_nan", "sensor_nan"}, E2EFault{"sensor_stuck", "sensor_stale"},
                                           E2EFault{"sensor_out_of_range", "sensor_out_of_range"},
                                           E2EFault{"sensor_dropout", "sensor_timeout"},
                                           E2EFault{"amplifier_fault", "amplifier_fault"}),
                         [](const auto& p) { return std::string(p.param.inject); });

struct BadConfig {
  const char* name;
  const char* toml_edit;  // appended to a copy of the sim config, or replacing a line
  const char* key;
};
void PrintTo(const BadConfig& c, std::ostream* os) { *os << c.name; }
class PvcgeldBadConfig : public ::testing::TestWithParam<BadConfig> {};

TEST_P(PvcgeldBadConfig, ExitsNonZeroNamingTheKey) {
  std::string text = slurp(kSimConfig);
  const std::string edit = GetParam().toml_edit;
  // Each edit is "old => new" on one line of the shipped sim config.
  const auto arrow = edit.find(" => ");
  const std::string from = edit.substr(0, arrow), to = edit.substr(arrow + 4);
  const auto pos = text.find(from);
  ASSERT_NE(pos, std::string::npos) << "test edit does not match the shipped config: " << from;
  // A table header as `from` replaces the whole table (up to the next blank line).
  const size_t len = from.front() == '[' ? text.find("\n\n", pos) - pos : from.size();
  text.replace(pos, len, to);
  const std::string path = ::testing::TempDir() + std::string("bad_") + GetParam().name + ".toml";
  std::ofstream(path) << text;
  const auto r = run_daemon({"--config", path, "--duration", "1"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(GetParam().key), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(path), std::string::npos) << "the message names the file: " << r.err;
}

INSTANTIATE_TEST_SUITE_P(
    EveryRule, PvcgeldBadConfig,
    ::testing::Values(
        BadConfig{"voltage_above_1000", "voltage_max_V = 1000.0 => voltage_max_V = 1200.0", "controller.voltage_max_V"},
        BadConfig{"voltage_below_0", "voltage_min_V = 0.0 => voltage_min_V = -10.0", "controller.voltage_min_V"},
        BadConfig{"inverse_not_monotone", "poly  = [0.1270, 1.3057e-5] => poly = [0.0721, 2.1307e-5, -1.7231e-11]",
                  "model.poly"},
        BadConfig{"closed_loop_unstable",
                  "[controller.tuning] => "
                  "[controller.pid.pid]\nkp = 500.0\n[controller.pid.inverse_pid]\nkp = 5000.0\n"
                  "[controller.pid.inverse_pid_dob]\nkp = 5000.0\n[controller.pid.inverse_pid_dob_ff]\nkp = 5000.0",
                  "controller.pid"},
        BadConfig{"q_ginv_improper", "G_num = [1.15, 1.03]         => G_num = [1.03]        ", "controller.dob.q_order"},
        BadConfig{"unknown_key", "ramp_down_V_per_s = 500.0 => ramp_dwn_V_per_s = 500.0", "safety.ramp_dwn_V_per_s"},
        BadConfig{"bad_type", "priority = 80 => priority = \"high\"", "loop.priority"}),
    [](const auto& p) { return std::string(p.param.name); });

}  // namespace

namespace {

// One error policy for the tools (pvcgel --help lists it): the same mistake
// gives the same exit code in every subcommand.
TEST(PvcgelExitCodes, TheSameMistakeGivesTheSameCodeInEverySubcommand) {
  const std::string bad_toml = ::testing::TempDir() + "exit_codes_bad.toml";
  std::ofstream(bad_toml) << "[model\npoly = [0.1]\n";
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"ident", "--sim", "--config", bad_toml},
        std::vector<std::string>{"bench", "paper", "--config", bad_toml}}) {
    const auto r = run_program(kClient, args);
    EXPECT_EQ(r.exit_code, 2) << args[0] << ": " << r.err;
    EXPECT_NE(r.err.find(bad_toml + ":1:"), std::string::npos) << r.err;
  }
  const auto daemon = run_program(kDaemon, {"--config", bad_toml, "--check-config"});
  EXPECT_EQ(daemon.exit_code, 2) << daemon.err;
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--no-such-option"}, std::vector<std::string>{"--duration", "-1"}}) {
    const auto r = run_program(kDaemon, args);
    EXPECT_EQ(r.exit_code, 64) << args[0] << ": " << r.err;
  }
  EXPECT_EQ(run_program(kDaemon, {"--help"}).exit_code, 0);
  for (const std::vector<std::string>& args : {std::vector<std::string>{"ident", "--no-such-option"},
                                               std::vector<std::string>{"show"}, std::vector<std::string>{}}) {
    const auto r = run_program(kClient, args);
    EXPECT_EQ(r.exit_code, 64) << r.err;
  }
  // A segment that does not fit its kind is a usage error, named before any rig is reached (no DDS starts).
  for (const auto& [args, message] :
       {std::pair<std::vector<std::string>, std::string>{{"send", "sine", "1", "2"}, "send sine takes OFFSET AMPLITUDE FREQ_HZ [PHASE_RAD]"},
        std::pair<std::vector<std::string>, std::string>{{"send", "paper", "2Hz"}, "send paper takes 0.1Hz, 0.5Hz, 1Hz or multi, not '2Hz'"}}) {
    const auto r = run_program(kClient, args);
    EXPECT_EQ(r.exit_code, 64) << r.err;
    EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
  }
  const auto help = run_program(kClient, {"--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("Exit codes (every subcommand)"), std::string::npos) << help.out;
}

}  // namespace
