// End to end over real Modbus TCP: the pvcgeld binary, configured from the shipped
// config/pvcgeld-modbus.toml (pointed at loopback, [hal.gpio] removed: no gpiochip
// here), runs closed loop against the pymodbus plant server. The loop runs at
// 100 Hz, not 1 kHz: pymodbus (Python) answers in ~0.2 ms p50 but ~1 ms p99 on a
// quiet machine and several ms on this shared 2-core one, which does not fit a
// 1 ms period (the start-up budget check would refuse it). This virtual machine
// also stalls whole for ~100 ms now and then (pvcgeld's own wake-up latency max
// shows it), so the closed-loop and server-kill tests tolerate 15 missed samples
// in a row (150 ms) instead of the shipped 3; the slow-server test keeps the shipped count.
#include <gtest/gtest.h>

#include <cmath>
#include <initializer_list>
#include <sstream>

#include "support/modbus_peer.hpp"
#include "tools/recording.hpp"

using namespace pvcgel;
using test::Child;
using test::PlantServer;

namespace {

const std::string kDaemon = PVCGELD_PATH;
const std::string kModbusConfig = std::string(PVCGEL_SOURCE_DIR) + "/config/pvcgeld-modbus.toml";

void replace_once(std::string& text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  if (pos == std::string::npos) throw std::runtime_error("config/pvcgeld-modbus.toml no longer contains '" + from + "'");
  text.replace(pos, from.size(), to);
}

/// The shipped lab configuration, pointed at the plant server on loopback at 100 Hz.
std::string loopback_config(const std::string& dir, int port, int unit_id = 1, bool tolerate_stalls = false,
                            bool keep_gpio = false) {
  std::string text = test::slurp(kModbusConfig);
  replace_once(text, "host = \"192.168.10.20\"", "host = \"127.0.0.1\"");
  replace_once(text, "port = 502", "port = " + std::to_string(port));
  replace_once(text, "unit_id = 1", "unit_id = " + std::to_string(unit_id));
  replace_once(text, "period_s = 0.001", "period_s = 0.010");
  replace_once(text, "io_budget_us = 600", "io_budget_us = 8000");
  replace_once(text, "response_timeout_us = 300", "response_timeout_us = 4000");
  if (tolerate_stalls) {
    replace_once(text, "sensor_timeout_cycles = 3", "sensor_timeout_cycles = 15");
    replace_once(text, "reconnect_after_failures = 10", "reconnect_after_failures = 40");
  }
  const auto gpio = text.find("[hal.gpio]"), safety = text.find("[safety]");
  if (gpio == std::string::npos || safety == std::string::npos) throw std::runtime_error("no [hal.gpio] / [safety]");
  if (!keep_gpio) text.erase(gpio, safety - gpio);
  const std::string path = dir + "/pvcgeld.toml";
  std::ofstream(path) << text;
  return path;
}

/// N from "hal modbus: link up, N timeouts, N exceptions, N garbage, N reconnects" in the stop summary; -1 if absent.
long summary_count(const std::string& err, const std::string& what) {
  const auto line = err.find("hal modbus:");
  if (line == std::string::npos) return -1;
  const auto pos = err.find(" " + what, line);
  if (pos == std::string::npos) return -1;
  const auto start = err.rfind(' ', pos - 1) + 1;
  return std::stol(err.substr(start, pos - start));
}

struct Daemon {
  std::string err_path;
  Child child;
  Daemon(const std::string& dir, std::vector<std::string> args) : err_path(dir + "/pvcgeld.err") {
    args.insert(args.begin(), kDaemon);
    child = Child(args, err_path);
  }
  [[nodiscard]] std::string err() const { return test::slurp(err_path); }
  bool wait_for_log(const std::string& s, double timeout_s) const {
    return test::wait_for([&] { return err().find(s) != std::string::npos; }, timeout_s);
  }
  /// The first of `reasons` the log names as "fault <reason>" (the later one in the list if several),
  /// waiting up to timeout_s; empty if none.
  [[nodiscard]] std::string wait_for_fault(std::initializer_list<const char*> reasons, double timeout_s) const {
    std::string seen;
    test::wait_for(
        [&] {
          for (const char* r : reasons)
            if (err().find(std::string("fault ") + r) != std::string::npos) seen = r;
          return !seen.empty();
        },
        timeout_s);
    return seen;
  }
};

}  // namespace

TEST(PvcgeldModbusE2E, ShippedExampleConfigurationIsValid) {
  Child check({kDaemon, "--check-config", "--config", kModbusConfig});
  EXPECT_EQ(check.wait(), 0);
}

TEST(PvcgeldModbusE2E, ClosedLoopOverModbusTcpTracksASine) {
  const std::string dir = test::scratch_dir("e2e_modbus");
  PlantServer server({.journal = dir + "/journal.txt"});
  const std::string cfg = loopback_config(dir, server.port(), 1, true);
  Daemon d(dir, {"--config", cfg, "--trajectory", "sine:100,40,0.5", "--duration", "4", "--record", dir + "/rec.csv"});
  const int code = d.child.wait();
  const std::string err = d.err();
  ASSERT_EQ(code, 0) << err;
  EXPECT_NE(err.find("modbus tcp 127.0.0.1:" + std::to_string(server.port()) + " unit 1: I/O per cycle p50"),
            std::string::npos) << err;
  EXPECT_NE(err.find("backend modbus"), std::string::npos) << err;
  const auto pos = err.find("modbus tcp");
  std::cout << "[rtt] " << err.substr(pos, err.find('\n', pos) - pos) << "\n";
  const auto sum = err.find("hal modbus:");
  ASSERT_NE(sum, std::string::npos) << err;
  std::cout << "[hal] " << err.substr(sum, err.find('\n', sum) - sum) << "\n";

  const auto rec = tools::read_recording(dir + "/rec.csv", true);  // keep missed samples (y NaN)
  EXPECT_EQ(rec.header.at("rate_hz"), "100");
  EXPECT_EQ(rec.header.at("hal_backend"), "modbus");
  const auto& state = rec.text.at("state");
  const auto& t = rec.col("t_s");
  const auto& e = rec.col("e_um");
  const auto& y = rec.col("y_um");
  double worst = 0.0, sum_sq = 0.0, y_min = 1e9, y_max = -1e9;
  long running = 0, missed = 0;
  for (size_t k = 0; k < e.size(); ++k) {
    if (!std::isfinite(y[k])) ++missed;
    if (state[k] == "RUNNING" && t[k] > 3.0 && std::isfinite(e[k])) {  // one second after the 2 s soft start
      worst = std::max(worst, std::abs(e[k]));
      sum_sq += e[k] * e[k];
      y_min = std::min(y_min, y[k]);
      y_max = std::max(y_max, y[k]);
      ++running;
    }
  }
  ASSERT_GT(running, 200);
  const double rms = std::sqrt(sum_sq / static_cast<double>(running));
  std::printf("[tracking] 100 +- 40 um at 0.5 Hz over Modbus TCP at 100 Hz: rms %.2f um, max %.2f um over %ld cycles; "
              "%ld of %zu samples missed (timeouts)\n", rms, worst, running, missed, e.size());
  EXPECT_EQ(missed, rec.invalid_rows) << "every missed sample is in the recording, as NaN";
  // The plant is the model here (plus 0.05 um noise and the real transport delay):
  // the measured output follows the sine's full swing with a few um of error
  // (rms 1.3 um, max 2-3.5 um in quiet runs; a 100 ms stall holds the output and can
  // cost up to the sine's slope x 0.1 s = 12.6 um).
  EXPECT_LT(rms, 3.0);
  EXPECT_LT(worst, 15.0);
  EXPECT_LT(y_min, 66.0);
  EXPECT_GT(y_max, 134.0);

  // The server saw the commands the daemon recorded, and 0 V last.
  const auto j = test::read_journal(dir + "/journal.txt");
  long writes = 0, max_counts = 0;
  for (const auto& line : j)
    if (line[0] == "W") {
      ++writes;
      max_counts = std::max(max_counts, std::stol(line[2]));
    }
  EXPECT_GT(writes, static_cast<long>(rec.rows()) - 5);
  double u_max = 0.0;
  for (double u : rec.col("u_V")) u_max = std::max(u_max, u);
  EXPECT_NEAR(static_cast<double>(max_counts) * 0.1, u_max, 0.1);
  EXPECT_EQ(j.front(), (std::vector<std::string>{"W", "10", "0"}));
  EXPECT_EQ(j.back(), (std::vector<std::string>{"W", "10", "0"}));
}

TEST(PvcgeldModbusE2E, ServerKilledMidRunFaultsAndZeroVoltsIsWrittenFirstOnReconnect) {
  const std::string dir = test::scratch_dir("e2e_modbus_kill");
  PlantServer server({.journal = dir + "/before.txt"});
  const int port = server.port();
  Daemon d(dir, {"--config", loopback_config(dir, port, 1, true), "--trajectory", "hold:80"});
  ASSERT_TRUE(d.wait_for_log("RUNNING", 15.0)) << d.err();
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));  // past the soft start, the amplifier well above 0 V
  long last_write = -1;
  for (const auto& line : test::read_journal(dir + "/before.txt"))
    if (line[0] == "W") last_write = std::stol(line[2]);
  EXPECT_GT(last_write, 1000) << "the amplifier was driven when the server died";

  server.kill();
  // The lost link is seen by whichever transaction of the cycle comes first: the
  // sensor read (hal_error) or the amplifier write (actuator_write_failed).
  const std::string reason = d.wait_for_fault({"hal_error", "actuator_write_failed"}, 5.0);
  ASSERT_FALSE(reason.empty()) << d.err();
  PlantServer again({.port = port, .journal = dir + "/after.txt"});
  ASSERT_TRUE(test::wait_for([&] { return !test::read_journal(dir + "/after.txt").empty(); }, 10.0)) << d.err();
  const auto after = test::read_journal(dir + "/after.txt");
  EXPECT_EQ(after.front(), (std::vector<std::string>{"W", "10", "0"})) << "0 V before anything else";
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  for (const auto& line : test::read_journal(dir + "/after.txt")) {
    if (line[0] == "W") {
      EXPECT_EQ(line[2], "0") << "after a lost link the register stays at 0 V (ramp-down or FAULT) until re-armed";
    }
  }
  d.child.signal(SIGTERM);
  // Asked to stop while waiting in FAULT it stops: exit 0 (the fault is in the log, checked below).
  EXPECT_EQ(d.child.wait(), 0) << d.err();
  const std::string err = d.err();
  EXPECT_NE(err.find("FAULT, fault " + reason), std::string::npos) << err;
  EXPECT_GE(summary_count(err, "reconnects"), 1) << err;
}

TEST(PvcgeldModbusE2E, SlowServerFaultsWithATimeoutAfterTheConfiguredCount) {
  const std::string dir = test::scratch_dir("e2e_modbus_slow");
  PlantServer server({.slow_ms = 50.0});
  Daemon d(dir, {"--config", loopback_config(dir, server.port()), "--trajectory", "hold:50"});
  ASSERT_TRUE(d.wait_for_log("RUNNING", 15.0)) << d.err();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  server.toggle_slow();
  // The server answers every read 50 ms late, so the third read in a row misses its
  // deadline (sensor_timeout). The writes queued behind those reads miss theirs too,
  // and when this machine stalls a read can still be answered in time between
  // them, so the third missed write can come first (actuator_write_failed). Either
  // is the configured count of timeouts. The late replies the loop receives meanwhile
  // are missed samples: a fault naming the link (hal_error) would be wrong.
  const std::string reason = d.wait_for_fault({"sensor_timeout", "actuator_write_failed", "hal_error"}, 5.0);
  ASSERT_FALSE(reason.empty()) << d.err();
  EXPECT_NE(reason, "hal_error") << d.err();
  server.toggle_slow();
  d.child.signal(SIGTERM);
  EXPECT_EQ(d.child.wait(), 0) << "SIGTERM while in FAULT: exit 0\n" << d.err();
  const std::string err = d.err();
  EXPECT_NE(err.find("stopped in state FAULT (fault: " + reason + ")"), std::string::npos) << err;
  EXPECT_GE(summary_count(err, "timeouts"), 3) << "at least sensor_timeout_cycles\n" << err;
  EXPECT_EQ(summary_count(err, "garbage"), 0) << err;
}

TEST(PvcgeldModbusE2E, WrongUnitIdIsAConfigurationErrorExitCode2) {
  const std::string dir = test::scratch_dir("e2e_modbus_unit");
  PlantServer server({.unit = 1});
  Daemon d(dir, {"--config", loopback_config(dir, server.port(), 9), "--trajectory", "hold:50"});
  EXPECT_EQ(d.child.wait(), 2) << d.err();
  EXPECT_NE(d.err().find("configuration error: hal.modbus.unit_id"), std::string::npos) << d.err();
}

TEST(PvcgeldModbusE2E, MissingGpioChipIsAConfigurationErrorBeforeTheAmplifierIsTouched) {
  if (std::filesystem::exists("/dev/gpiochip0")) GTEST_SKIP() << "this machine has a gpiochip0";
  const std::string dir = test::scratch_dir("e2e_modbus_gpio");
  PlantServer server({.journal = dir + "/journal.txt"});
  Daemon d(dir, {"--config", loopback_config(dir, server.port(), 1, false, true), "--trajectory", "hold:50"});
  EXPECT_EQ(d.child.wait(), 2) << d.err();
  EXPECT_NE(d.err().find("configuration error: hal.gpio.chip"), std::string::npos) << d.err();
  EXPECT_TRUE(test::read_journal(dir + "/journal.txt").empty()) << "the interlock is set up before any Modbus request";
}
