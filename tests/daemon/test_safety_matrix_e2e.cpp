// The safety fault matrix (issue 12), end to end with the real pvcgeld binary
// (sim backend), the pvcgel client over DDS on loopback, and the tools reading
// the recordings. Each row reproduces a finding of the review: the largest
// per-cycle steps are compared with the limits, reset semantics with the
// fault still present, write and enable faults, refused configurations, and
// recordings cut by SIGKILL.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <thread>

#include "support/subprocess.hpp"
#include "tools/recording.hpp"

namespace {

namespace fs = std::filesystem;
using pvcgel::test::Process;
using pvcgel::test::Result;
using pvcgel::test::run_program;
using pvcgel::test::slurp;

const std::string kDaemon = PVCGELD_PATH;
const std::string kClient = PVCGEL_PATH;
const std::string kSource = PVCGEL_SOURCE_DIR;
const std::string kDdsConfig = kSource + "/config/cyclonedds-loopback.xml";
const int kDomain = pvcgel::test::unique_dds_domain();

// The shipped defaults the limits below come from ([setpoints] and [safety]).
constexpr double kMaxRefStep_um = 0.5;   // min(max_step_um 2, max_slope_um_per_s 500 * 1 ms)
constexpr double kMaxSlew_V = 30.0;      // output_slew_V_per_s 30000 * 1 ms
constexpr double kRamp_V = 0.5;          // ramp_down_V_per_s 500 * 1 ms

std::string tmp(const std::string& name) { return ::testing::TempDir() + "safety_" + std::to_string(getpid()) + "_" + name; }

/// The shipped sim config on this process's domain as `rig`; idle (no trajectory) unless `keep_trajectory`.
std::string config(const std::string& rig, bool keep_trajectory = false, const std::string& max_lead_s = "10.0") {
  std::string text = slurp(kSource + "/config/pvcgeld-sim.toml");
  text = std::regex_replace(text, std::regex("\nmax_lead_s = 10.0"), "\nmax_lead_s = " + max_lead_s);
  if (!keep_trajectory) text = std::regex_replace(text, std::regex("\ntrajectory = [^\n]*"), "\n");
  text = std::regex_replace(text, std::regex("\ndomain = 0"), "\ndomain = " + std::to_string(kDomain));
  text = std::regex_replace(text, std::regex("\nrig_id = \"rig1\""), "\nrig_id = \"" + rig + "\"");
  text = std::regex_replace(text, std::regex("config = \"cyclonedds-loopback.xml\""), "config = \"" + kDdsConfig + "\"");
  const std::string path = tmp(rig + ".toml");
  std::ofstream(path) << text;
  return path;
}

std::vector<std::string> client_args(std::vector<std::string> args, const std::string& rig) {
  args.insert(args.end(), {"--rig", rig, "--domain", std::to_string(kDomain), "--dds-config", kDdsConfig, "--wait", "10"});
  return args;
}
Result client(std::vector<std::string> args, const std::string& rig) { return run_program(kClient, client_args(std::move(args), rig)); }

/// Wait until the daemon's stderr contains `text` (false after `timeout_s`).
bool wait_for(const Process& p, const std::string& text, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    if (p.err_so_far().find(text) != std::string::npos) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}
void sleep_s(double s) { std::this_thread::sleep_for(std::chrono::duration<double>(s)); }

std::string csv_const(const std::string& name, double level, int rows) {
  const std::string path = tmp(name);
  std::ofstream f(path);
  f << "t_s,r_um\n";
  for (int i = 0; i < rows; ++i) f << i * 1e-3 << "," << level << "\n";
  return path;
}

/// The largest per-cycle changes in a recording: the reference between RUNNING
/// rows, the voltage outside the fault/stop ramp (which is checked on its own).
struct Steps {
  double max_dr_um = 0.0, max_du_V = 0.0, max_ramp_du_V = 0.0;
  size_t running_rows = 0;
};
Steps steps(const pvcgel::tools::Recording& rec) {
  const auto& u = rec.col("u_V");
  const auto& r = rec.col("r_um");
  const auto& state = rec.text.at("state");
  Steps s;
  for (size_t k = 1; k < u.size(); ++k) {
    const bool ramp = state[k - 1] == "RAMP_DOWN";  // a cycle that starts in the ramp
    (ramp ? s.max_ramp_du_V : s.max_du_V) = std::max(ramp ? s.max_ramp_du_V : s.max_du_V, std::abs(u[k] - u[k - 1]));
    if (state[k] == "RUNNING" && state[k - 1] == "RUNNING") {
      s.max_dr_um = std::max(s.max_dr_um, std::abs(r[k] - r[k - 1]));
      ++s.running_rows;
    }
  }
  std::printf("[steps] largest per-cycle reference step %.4f um (limit %.3f), voltage step %.3f V (limit %.1f), "
              "ramp step %.3f V (rate %.1f V/cycle), over %zu RUNNING rows\n",
              s.max_dr_um, kMaxRefStep_um, s.max_du_V, kMaxSlew_V, s.max_ramp_du_V, kRamp_V, s.running_rows);
  return s;
}

}  // namespace

// Row 1: a 2 s blend on a CSV chunk (cut into 128-sample pieces) and two clients
// streaming CSV at once never step the played reference or the voltage.
TEST(SafetyMatrixE2E, CsvBlendAndTwoInterleavingClientsNeverStepTheOutput) {
  const std::string rec_path = tmp("blend.csv");
  // A short queue (1.5 s ahead) makes the two clients below take turns under back-pressure: their chunks interleave.
  Process d(kDaemon, {"--config", config("blend", false, "1.5"), "--record", rec_path});
  ASSERT_TRUE(wait_for(d, "loop running", 20)) << d.err_so_far();
  ASSERT_EQ(client({"start"}, "blend").exit_code, 0);
  ASSERT_EQ(client({"send", "hold", "80", "--blend", "1"}, "blend").exit_code, 0);
  sleep_s(2.5);
  const auto blended = client({"send", "csv", csv_const("const100.csv", 100.0, 3000), "--blend", "2"}, "blend");
  EXPECT_EQ(blended.exit_code, 0) << blended.err;
  sleep_s(3.5);
  // Two clients appending CSV at the same time, 30 um apart: the loop refuses the chunk that would step
  // (step_too_large) or plays it blended; the output never steps either way.
  Process a(kClient, client_args({"send", "csv", csv_const("a.csv", 100.0, 4000), "--append"}, "blend"));
  Process b(kClient, client_args({"send", "csv", csv_const("b.csv", 130.0, 4000), "--append"}, "blend"));
  const Result ra = a.wait(), rb = b.wait();
  std::printf("[clients] a exit %d, b exit %d: %s\n", ra.exit_code, rb.exit_code, rb.err.substr(0, 300).c_str());
  sleep_s(2.0);
  const Result rd = d.stop();
  ASSERT_EQ(rd.exit_code, 0) << rd.err;
  const auto rec = pvcgel::tools::read_recording(rec_path, true);
  const Steps s = steps(rec);
  EXPECT_GT(s.running_rows, 8000u);
  EXPECT_LE(s.max_dr_um, kMaxRefStep_um + 1e-9);
  EXPECT_LE(s.max_du_V, kMaxSlew_V + 1e-9);
  bool reached_100 = false;
  for (double r : rec.col("r_um")) reached_100 = reached_100 || std::abs(r - 100.0) < 1e-6;
  EXPECT_TRUE(reached_100) << "the blended chunk played";
}

// Row 2: local trajectories pass the same [setpoints] checks as DDS ones.
TEST(SafetyMatrixE2E, LocalTrajectoriesBeyondTheLimitsAreRefused) {
  const auto hold = run_program(kDaemon, {"--config", config("local"), "--trajectory", "hold:5000", "--duration", "1"});
  EXPECT_EQ(hold.exit_code, 2) << hold.err;
  EXPECT_NE(hold.err.find("trajectory"), std::string::npos) << hold.err;
  EXPECT_NE(hold.err.find("300"), std::string::npos) << "names the limit: " << hold.err;
  const std::string step = tmp("step.csv");
  std::ofstream(step) << "t_s,r_um\n0,50\n1,50\n1.001,100\n2,100\n";
  const auto csv = run_program(kDaemon, {"--config", config("local"), "--trajectory", "csv:" + step, "--duration", "1"});
  EXPECT_EQ(csv.exit_code, 2) << csv.err;
  EXPECT_NE(csv.err.find(step + ":4"), std::string::npos) << "names file:line: " << csv.err;
}

// Row 3: reset with the fault still present: FAULT -> DISABLED, high voltage
// off, never re-armed; arming is refused naming the cause; SIGTERM exits 0.
TEST(SafetyMatrixE2E, ResetWithTheFaultPresentStaysDisabledAndArmIsRefusedNamingTheCause) {
  const std::string rec_path = tmp("reset.csv");
  Process d(kDaemon, {"--config", config("reset", true), "--trajectory", "paper-1hz", "--record", rec_path,
                      "--inject-fault", "amplifier_fault@3"});
  ASSERT_TRUE(wait_for(d, "FAULT, fault amplifier_fault", 30)) << d.err_so_far();
  kill(d.pid(), SIGUSR1);
  ASSERT_TRUE(wait_for(d, "DISABLED", 5)) << d.err_so_far();
  sleep_s(1.0);
  const auto arm = client({"arm"}, "reset");
  EXPECT_EQ(arm.exit_code, 4) << arm.out << arm.err;
  EXPECT_NE((arm.out + arm.err).find("amplifier_fault"), std::string::npos) << "the refusal names the cause: " << arm.err;
  sleep_s(0.5);
  const Result rd = d.stop();
  EXPECT_EQ(rd.exit_code, 0) << rd.err;
  const auto rec = pvcgel::tools::read_recording(rec_path, true);
  const auto& state = rec.text.at("state");
  const auto& hv = rec.col("hv");
  size_t first_fault = 0;
  while (first_fault < state.size() && state[first_fault] != "FAULT") ++first_fault;
  ASSERT_LT(first_fault, state.size());
  bool disabled_seen = false;
  for (size_t k = first_fault; k < state.size(); ++k) {
    ASSERT_EQ(hv[k], 0.0) << "high voltage came on after the fault at t = " << rec.col("t_s")[k];
    ASSERT_TRUE(state[k] == "FAULT" || state[k] == "DISABLED") << state[k] << " at t = " << rec.col("t_s")[k];
    disabled_seen = disabled_seen || state[k] == "DISABLED";
  }
  EXPECT_TRUE(disabled_seen);
}

TEST(SafetyMatrixE2E, SigtermWhileWaitingInFaultExitsZero) {
  Process d(kDaemon, {"--config", config("term", true), "--trajectory", "paper-1hz", "--inject-fault", "sensor_nan@1"});
  ASSERT_TRUE(wait_for(d, "FAULT, fault sensor_nan", 30)) << d.err_so_far();
  const Result r = d.stop();
  EXPECT_EQ(r.exit_code, 0) << "asked to stop, it stopped (README): " << r.err;
}

// Row 4: write and enable faults: a reason code, 0 V, high voltage off, exit 3.
struct ActuatorFault {
  const char* inject;
  const char* reason;
};
void PrintTo(const ActuatorFault& f, std::ostream* os) { *os << f.inject; }
class SafetyActuatorFault : public ::testing::TestWithParam<ActuatorFault> {};

TEST_P(SafetyActuatorFault, ReasonZeroVoltsHighVoltageOffExit3) {
  const std::string rec_path = tmp(std::string("act_") + GetParam().inject + ".csv");
  const auto r = run_program(kDaemon, {"--config", config(std::string("act") + GetParam().inject, true), "--trajectory",
                                       "paper-1hz", "--duration", "8", "--record", rec_path, "--inject-fault",
                                       GetParam().inject});
  ASSERT_EQ(r.signal, 0) << r.err;
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find(std::string("fault: ") + GetParam().reason), std::string::npos) << r.err;
  // Parsed by hand: a run whose arm fails ends after one row, too short for the tools' reader.
  std::ifstream in(rec_path);
  std::vector<std::vector<std::string>> rows;
  std::vector<std::string> names;
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    (names.empty() ? names : rows.emplace_back()) = cells;
  }
  const auto col = [&](const char* name) {
    return static_cast<size_t>(std::find(names.begin(), names.end(), name) - names.begin());
  };
  size_t first = 0;
  while (first < rows.size() && rows[first][col("fault")] != GetParam().reason) ++first;
  ASSERT_LT(first, rows.size()) << "reason code in the recording";
  // The amplifier cannot be commanded down (or was never enabled): high voltage is off at once, not after a ramp.
  EXPECT_EQ(rows[first][col("hv")], "0") << "hv at the first faulted row";
  EXPECT_EQ(rows.back()[col("state")], "FAULT");
  EXPECT_EQ(std::stod(rows.back()[col("u_V")]), 0.0);
  EXPECT_EQ(rows.back()[col("hv")], "0");
  if (rows.size() < 2) return;
  const auto show = run_program(kClient, {"show", rec_path});
  EXPECT_NE(show.out.find("final state FAULT, output 0.000 V, high voltage disabled"), std::string::npos) << show.out;
}

INSTANTIATE_TEST_SUITE_P(WriteAndEnable, SafetyActuatorFault,
                         ::testing::Values(ActuatorFault{"write_failed@3", "actuator_write_failed"},
                                           ActuatorFault{"write_timeout@3", "actuator_write_failed"},
                                           ActuatorFault{"hv_enable_failed@0", "hv_enable_failed"}),
                         [](const auto& p) { return std::string(p.param.reason) + "_" + std::to_string(p.index); });

// Row 5: start from rest and restart after a stop (the gel still relaxing): no voltage step.
TEST(SafetyMatrixE2E, StartAndRestartNeverStepTheVoltage) {
  const std::string rec_path = tmp("restart.csv");
  Process d(kDaemon, {"--config", config("restart"), "--record", rec_path});
  ASSERT_TRUE(wait_for(d, "loop running", 20)) << d.err_so_far();
  ASSERT_EQ(client({"start"}, "restart").exit_code, 0);
  ASSERT_EQ(client({"send", "hold", "40", "--blend", "1"}, "restart").exit_code, 0);
  sleep_s(3.0);
  const auto stop = client({"stop"}, "restart");
  EXPECT_EQ(stop.exit_code, 0);
  EXPECT_EQ(stop.out.find("now RUNNING"), std::string::npos) << "the state printed is the fresh one: " << stop.out;
  sleep_s(1.0);  // ramped down; y still near 40 um
  const auto start = client({"start"}, "restart");
  EXPECT_EQ(start.exit_code, 0) << start.err;
  EXPECT_NE(start.out.find("now RUNNING"), std::string::npos) << start.out;
  sleep_s(1.5);
  const auto again = client({"start"}, "restart");
  EXPECT_NE(again.out.find("already RUNNING"), std::string::npos) << "start while RUNNING says so: " << again.out;
  const Result rd = d.stop();
  ASSERT_EQ(rd.exit_code, 0) << rd.err;
  const Steps s = steps(pvcgel::tools::read_recording(rec_path, true));
  EXPECT_LE(s.max_du_V, kMaxSlew_V + 1e-9);
  EXPECT_LE(s.max_ramp_du_V, kRamp_V + 1e-9);
  EXPECT_LE(s.max_dr_um, kMaxRefStep_um + 1e-9);
}

// Row 6: configurations that must be refused, each naming the key and its bound.
struct Refused {
  const char* name;
  const char* from;  // regex on the shipped sim config ("" : write `to` as the whole file)
  const char* to;
  const char* expect;
};
void PrintTo(const Refused& c, std::ostream* os) { *os << c.name; }
class SafetyRefusedConfig : public ::testing::TestWithParam<Refused> {};

TEST_P(SafetyRefusedConfig, ExitsTwoNamingTheKeyAndBound) {
  const Refused& c = GetParam();
  std::string path = tmp(std::string("refused_") + c.name + ".toml");
  if (std::string(c.name) == "directory") {
    path = ::testing::TempDir();
  } else if (std::string(c.name) == "modbus_without_model") {
    const std::string text = slurp(kSource + "/config/pvcgeld-modbus.toml");
    std::ofstream(path) << std::regex_replace(text, std::regex("\\[model\\][\\s\\S]*?\n(?=\\[controller\\])"), "");
  } else if (*c.from == 0) {
    std::ofstream(path) << c.to;
  } else {
    std::ofstream(path) << std::regex_replace(slurp(config("refused")), std::regex(c.from), c.to);
  }
  const auto r = run_program(kDaemon, {"--config", path, "--check-config"});
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
  EXPECT_NE(r.err.find(c.expect), std::string::npos) << r.err;
}

INSTANTIATE_TEST_SUITE_P(
    Every, SafetyRefusedConfig,
    ::testing::Values(Refused{"empty", "", "", "is empty"}, Refused{"directory", "", "", "is a directory"},
                      Refused{"modbus_without_model", "", "", "needs its own identified [model]"},
                      Refused{"ramp_absurd", "ramp_down_V_per_s = 500.0", "ramp_down_V_per_s = 1e300",
                              "safety.ramp_down_V_per_s: 1e+300 is outside 1..30000"},
                      Refused{"slew_absurd", "output_slew_V_per_s = 30000.0", "output_slew_V_per_s = 1e9",
                              "safety.output_slew_V_per_s: 1e+09 is outside 1..1e+06"},
                      Refused{"period_names_its_key", "period_s = 0.001", "period_s = 0.0", "controller.period_s"}),
    [](const auto& p) { return std::string(p.param.name); });

// Row 7: a recording cut by SIGKILL is read by every tool; a fault at the end is
// reported as it is; a non-physical value is flagged with file:line.
TEST(SafetyMatrixE2E, SigkilledRecordingIsReadByEveryToolAndShowTellsTheTruth) {
  const std::string dir = tmp("killed");
  fs::create_directories(dir);
  const std::string rec_path = dir + "/killed.csv";
  Process d(kDaemon, {"--config", config("killed", true), "--trajectory", "paper-1hz", "--record", rec_path});
  ASSERT_TRUE(wait_for(d, "loop running", 20));
  sleep_s(7.0);  // diagnose needs 3 time constants of G's slowest pole (5.7 s)
  d.stop(SIGKILL);
  // SIGKILL cuts wherever the last buffer ended; make sure the last line is cut, as it then usually is.
  std::string text = slurp(rec_path);
  ASSERT_GT(text.size(), 1000u);
  if (text.back() == '\n') text.resize(text.size() - 7);
  std::ofstream(rec_path, std::ios::trunc) << text;
  const auto show = run_program(kClient, {"show", rec_path});
  EXPECT_EQ(show.exit_code, 0) << show.err;
  EXPECT_NE(show.out.find("last line cut"), std::string::npos) << show.out;
  const auto diagnose = run_program(kClient, {"diagnose", "--model", kSource + "/config/paper-rig.toml", rec_path});
  EXPECT_EQ((diagnose.out + diagnose.err).find("fields, header has"), std::string::npos) << diagnose.err;
  EXPECT_EQ(diagnose.exit_code, 0) << diagnose.err;
  const auto ident = run_program(kClient, {"ident", "--from", dir, "--out", dir + "/model.toml"});
  EXPECT_EQ((ident.out + ident.err).find("fields, header has"), std::string::npos) << ident.err;

  // The false summary: a recording ending in a sensor fault.
  const std::string nan_path = tmp("nan.csv");
  ASSERT_EQ(run_program(kDaemon, {"--config", config("nan", true), "--trajectory", "paper-1hz", "--duration", "5",
                                  "--record", nan_path, "--inject-fault", "sensor_nan@3"})
                .exit_code,
            3);
  const auto truth = run_program(kClient, {"show", nan_path});
  EXPECT_NE(truth.out.find("final state FAULT, output 0.000 V, high voltage disabled"), std::string::npos) << truth.out;

  std::string bad = slurp(nan_path);
  const auto row = bad.find("\n", bad.find("t_s,u_V")) + 1;
  const auto comma = bad.find(',', row);
  bad.replace(comma + 1, bad.find(',', comma + 1) - comma - 1, "1e308");
  const std::string bad_path = tmp("nonphysical.csv");
  std::ofstream(bad_path) << bad;
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"show", bad_path},
        std::vector<std::string>{"diagnose", "--model", kSource + "/config/paper-rig.toml", bad_path}}) {
    const auto r = run_program(kClient, args);
    EXPECT_NE(r.exit_code, 0) << args[0];
    EXPECT_NE(r.err.find(bad_path + ":12: u_V = 1e308 is not physical"), std::string::npos) << args[0] << ": " << r.err;
  }
}
