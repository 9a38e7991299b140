// DDS benchmark (not a test): setpoint-to-actuation latency and lossless
// telemetry at 1 kHz, beside Cyclone's own ddsperf ping-pong measured in the
// same run on loopback.
//
//   bench_dds [--duration 60] [--domain 21]
//
// Target (the DDS issue): p99 setpoint latency <= one loop period + 2 x
// ddsperf's p99 one-way latency; 0 telemetry samples lost with a reliable reader.
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tools/dds_client.hpp"

extern char** environ;

namespace {

const std::string kSource = PVCGEL_SOURCE_DIR;
const std::string kDdsConfig = kSource + "/config/cyclonedds-loopback.xml";

pid_t spawn(std::vector<std::string> args, const std::string& out_path) {
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  if (posix_spawnp(&pid, args[0].c_str(), &fa, nullptr, argv.data(), environ) != 0) {
    std::fprintf(stderr, "bench_dds: cannot start %s\n", args[0].c_str());
    std::exit(1);
  }
  posix_spawn_file_actions_destroy(&fa);
  return pid;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

struct PingPong {
  double p50_rtt_us = NAN, p99_rtt_us = NAN;
  int intervals = 0;
};

/// ddsperf ping at 1 kHz against a ddsperf pong, both on the loopback config.
PingPong ddsperf(int domain, int seconds) {
  const std::string dir = "/tmp/bench_dds_" + std::to_string(getpid());
  const std::string d = std::to_string(domain);
  const pid_t pong = spawn({"ddsperf", "-i", d, "-D", std::to_string(seconds + 2), "pong"}, dir + "_pong.txt");
  const pid_t ping = spawn({"ddsperf", "-i", d, "-D", std::to_string(seconds), "ping", "1000Hz"}, dir + "_ping.txt");
  waitpid(ping, nullptr, 0);
  kill(pong, SIGTERM);
  waitpid(pong, nullptr, 0);
  std::ifstream f(dir + "_ping.txt");
  const std::regex line(R"(size \d+ mean [\d.]+us min [\d.]+us 50% ([\d.]+)us 90% [\d.]+us 99% ([\d.]+)us)");
  std::vector<double> p50, p99;
  std::string s;
  while (std::getline(f, s)) {
    std::smatch m;
    if (std::regex_search(s, m, line)) {
      p50.push_back(std::stod(m[1]));
      p99.push_back(std::stod(m[2]));
    }
  }
  PingPong r;
  r.intervals = static_cast<int>(p50.size());
  if (p50.size() > 1) {  // the first interval includes discovery
    p50.erase(p50.begin());
    p99.erase(p99.begin());
  }
  r.p50_rtt_us = percentile(p50, 0.5);
  r.p99_rtt_us = percentile(p99, 0.5);
  return r;
}

/// Telemetry sequence accounting, over both phases: samples received and lost (gaps in `seq`).
struct TelemetryTally {
  std::uint64_t received = 0, gaps = 0, last_seq = 0;
  bool first = true;
  void add(const pvcgel_v1_Telemetry& s) {
    if (!first && s.seq != last_seq + 1) gaps += s.seq - last_seq - 1;
    first = false;
    last_seq = s.seq;
    ++received;
  }
};

/// pvcgeld on the sim backend, idle, reliable telemetry on `domain`; returns its pid and the config it runs.
std::pair<pid_t, std::string> start_daemon(int domain) {
  std::ifstream sim(kSource + "/config/pvcgeld-sim.toml");
  std::stringstream text;
  text << sim.rdbuf();
  std::string cfg = text.str();
  cfg = std::regex_replace(cfg, std::regex("\ntrajectory = [^\n]*"), "\n");
  cfg = std::regex_replace(cfg, std::regex("\ndomain = 0"), "\ndomain = " + std::to_string(domain));
  cfg = std::regex_replace(cfg, std::regex("config = \"cyclonedds-loopback.xml\""), "config = \"" + kDdsConfig + "\"");
  const std::string cfg_path = "/tmp/bench_dds_" + std::to_string(getpid()) + ".toml";
  std::ofstream(cfg_path) << cfg;
  return {spawn({PVCGELD_PATH, "--config", cfg_path}, "/dev/null"), cfg_path};
}

/// A one-sample hold trajectory at `level` (kind 1, start now), pointing into `level`'s storage.
pvcgel_v1_Trajectory hold_at(std::vector<double>& level, double blend_s) {
  pvcgel_v1_Trajectory t{};
  t.kind = 1;
  t.start_time_s = -1;
  t.blend_s = blend_s;
  t.values._buffer = level.data();
  t.values._length = t.values._maximum = 1;
  return t;
}

/// Setpoints every ~50 ms for `duration_s` (after the soft start) and reliable telemetry: the latency from
/// each publish to the first cycle that applies it. `published` keeps the setpoints never seen applied.
std::vector<double> setpoint_latency_us(pvcgel::tools::DdsClient& c, double duration_s, TelemetryTally& tally,
                                        std::map<std::uint64_t, std::int64_t>& published) {
  std::vector<double> latency_us;
  std::vector<double> level{0.0};
  pvcgel_v1_Trajectory t = hold_at(level, 0.0);
  const auto start = std::chrono::steady_clock::now();
  auto next_send = start + std::chrono::seconds(3);  // after the soft start
  while (std::chrono::steady_clock::now() - start < std::chrono::duration<double>(duration_s)) {
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_send && now - start < std::chrono::duration<double>(duration_s - 0.5)) {
      level[0] = 1.0 + 0.5 * static_cast<double>(published.size() % 2);
      const auto seq = c.publish_trajectory(t);
      published[seq] = t.publish_time_ns;
      next_send += std::chrono::microseconds(50137);  // not a multiple of the period: every phase is sampled
    }
    for (const auto& s : c.take_telemetry(4096)) {
      tally.add(s);
      if (auto it = published.find(s.chunk_seq); it != published.end()) {
        latency_us.push_back(static_cast<double>(s.stamp_ns - it->second) * 1e-3);
        published.erase(it);  // the first cycle that applied it
      }
    }
    c.take_replies();
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  return latency_us;
}

/// The loop's wake-up latency (from telemetry) for 10 s quiet, then 10 s while a second client publishes
/// chunks and commands as fast as it can.
struct Flood {
  std::vector<double> quiet_latency_us, flood_latency_us;
  std::uint64_t published = 0;
};

Flood flood(pvcgel::tools::DdsClient& c, const pvcgel::tools::ClientOptions& o, TelemetryTally& tally) {
  Flood f;
  pvcgel::tools::DdsClient flooder(o);
  flooder.connect();
  std::vector<double> level{1.0};
  pvcgel_v1_Trajectory t = hold_at(level, 0.5);  // publishing stamps it
  const auto collect = [&](std::vector<double>& into, double seconds, bool flooding) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
      if (flooding) {
        level[0] = 1.0 + 0.5 * static_cast<double>(f.published % 2);
        flooder.publish_trajectory(t);
        flooder.publish_command(pvcgel::daemon::CommandKind::set_mode, 2);
        f.published += 2;
        if (f.published % 256 == 0) flooder.take_replies();
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      for (const auto& s : c.take_telemetry(4096)) {
        tally.add(s);
        into.push_back(s.latency_us);
      }
    }
  };
  collect(f.quiet_latency_us, 10.0, false);
  collect(f.flood_latency_us, 10.0, true);
  return f;
}

}  // namespace

int main(int argc, char** argv) {
  double duration_s = 60.0;
  int domain = 21;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (std::string(argv[i]) == "--duration") duration_s = std::atof(argv[i + 1]);
    else if (std::string(argv[i]) == "--domain") domain = std::atoi(argv[i + 1]);
  }
  setenv("CYCLONEDDS_URI", ("file://" + kDdsConfig).c_str(), 1);

  std::printf("ddsperf ping-pong at 1 kHz, 10 s, loopback ...\n");
  std::fflush(stdout);
  const PingPong pp = ddsperf(domain + 1, 10);
  std::printf("  ddsperf round trip p50 %.1f us, p99 %.1f us (median of %d one-second intervals)\n", pp.p50_rtt_us,
              pp.p99_rtt_us, pp.intervals);

  const auto [daemon, cfg_path] = start_daemon(domain);
  pvcgel::tools::ClientOptions o;
  o.domain = domain;
  o.dds_config = kDdsConfig;
  o.wait_s = 10.0;
  pvcgel::tools::DdsClient c(o, true, true);
  c.connect();
  c.command(pvcgel::daemon::CommandKind::arm);
  c.command(pvcgel::daemon::CommandKind::start);
  const double period_s = c.status().period_s;

  std::printf("pvcgeld: setpoints every 50 ms and reliable telemetry for %.0f s ...\n", duration_s);
  std::fflush(stdout);
  TelemetryTally tally;
  std::map<std::uint64_t, std::int64_t> published;  // chunk_seq -> publish time
  const auto latency_us = setpoint_latency_us(c, duration_s, tally, published);
  std::printf("flood: a second client publishing as fast as it can for 10 s ...\n");
  std::fflush(stdout);
  const Flood f = flood(c, o, tally);
  const auto status = c.fresh_status();
  kill(daemon, SIGTERM);
  waitpid(daemon, nullptr, 0);
  std::remove(cfg_path.c_str());

  const double p50 = percentile(latency_us, 0.5), p99 = percentile(latency_us, 0.99);
  const double target_us = period_s * 1e6 + 2.0 * (pp.p99_rtt_us / 2.0);
  std::printf("\nsetpoint -> actuation latency (client publish to the cycle that applies it), %zu setpoints:\n",
              latency_us.size());
  std::printf("  p50 %.1f us, p99 %.1f us, max %.1f us\n", p50, p99, percentile(latency_us, 1.0));
  std::printf("  target p99 <= period %.0f us + 2 x ddsperf p99 one-way %.1f us = %.1f us: ratio %.2f (%s)\n",
              period_s * 1e6, pp.p99_rtt_us / 2.0, target_us, p99 / target_us, p99 <= target_us ? "met" : "NOT met");
  std::printf("  (ddsperf one-way p50 %.1f us; pvcgel p50 / ddsperf one-way p50 = %.1f)\n", pp.p50_rtt_us / 2.0,
              p50 / (pp.p50_rtt_us / 2.0));
  std::printf("telemetry at %.0f Hz, reliable reader: %llu samples received, %llu lost (sequence gaps), %zu setpoints never seen applied\n",
              1.0 / period_s, static_cast<unsigned long long>(tally.received), static_cast<unsigned long long>(tally.gaps),
              published.size());
  const double q999 = percentile(f.quiet_latency_us, 0.999), f999 = percentile(f.flood_latency_us, 0.999);
  std::printf("flood: %llu messages in 10 s, %u refused as rate_limited; loop still %s\n",
              static_cast<unsigned long long>(f.published),
              status.rejects_by_reason[static_cast<int>(pvcgel::daemon::RejectReason::rate_limited)],
              status.state == 2 ? "RUNNING" : "NOT RUNNING");
  std::printf("  wake-up latency p99.9: quiet %.0f us, during the flood %.0f us: ratio %.2f (target <= 1.20: %s)\n", q999,
              f999, f999 / q999, f999 <= 1.2 * q999 ? "met" : "NOT met");
  return 0;
}
