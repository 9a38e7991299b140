#include "tools/client_commands.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <thread>

#include "control/controller.hpp"
#include "control/reference_signal.hpp"
#include "daemon/control_loop.hpp"
#include "daemon/dds/dds_messages.hpp"
#include "tools/dds_client.hpp"
#include "tools/text_output.hpp"

namespace pvcgel::tools {

namespace {

using daemon::CommandKind;
using daemon::LoopState;
using SegmentKind = daemon::SetpointSegment::Kind;

volatile std::sig_atomic_t g_interrupted = 0;

std::string state_line(const pvcgel_v1_Status& s) {
  // Decoded one by one, in the order printed: the first unknown value is the one named.
  const auto state = state_of(s);
  const auto fault = fault_of(s);
  const auto mode = dds::checked_from_wire<control::ControllerMode>(s.mode, "Status.mode");
  const auto target = dds::checked_from_wire<daemon::LoopTarget>(s.target, "Status.target");
  const bool faulted = fault != daemon::FaultReason::none;
  return format("%s%s%s%s, mode %s, target %s, HV %s, t %.3f s, queued to %s", daemon::to_string(state).data(),
                faulted ? " (fault " : "", faulted ? daemon::to_string(fault).data() : "", faulted ? ")" : "",
                control::to_string(mode).data(), daemon::to_string(target).data(), s.high_voltage ? "on" : "off", s.t_s,
                s.queued_until_s > s.t_s ? format("%.3f s", s.queued_until_s).c_str() : "(nothing)");
}

void print_status(const pvcgel_v1_Status& s) {
  std::printf("rig %s: %s\n", s.rig_id, state_line(s).c_str());
  std::printf("  pvcgeld %s, hal %s, config %s, period %.3f ms\n", s.version, s.hal_backend, s.config_hash,
              s.period_s * 1e3);
  std::printf("  loop: %llu cycles, %llu overruns, %llu records dropped; wake-up latency p50 %.0f us, p99 %.0f us, "
              "p99.9 %.0f us, max %.0f us; compute p99 %.0f us\n",
              static_cast<unsigned long long>(s.cycles), static_cast<unsigned long long>(s.overruns),
              static_cast<unsigned long long>(s.records_dropped), s.latency_p50_us, s.latency_p99_us,
              s.latency_p999_us, s.latency_max_us, s.compute_p99_us);
  std::printf("  inputs: %llu chunks and %llu commands accepted, %llu rejected",
              static_cast<unsigned long long>(s.chunks_accepted), static_cast<unsigned long long>(s.commands_accepted),
              static_cast<unsigned long long>(s.rejects_total));
  std::string by;
  for (std::size_t i = 1; i < std::size(s.rejects_by_reason); ++i)
    if (s.rejects_by_reason[i] > 0) {
      // A counter this client has no name for (a newer daemon) is shown by its number, not dropped.
      const auto reason = from_wire<daemon::RejectReason>(static_cast<std::uint8_t>(i));
      by += (by.empty() ? "" : ", ") + (reason ? std::string(daemon::to_string(*reason)) : "reason " + std::to_string(i)) +
            " " + std::to_string(s.rejects_by_reason[i]);
    }
  if (!by.empty())
    std::printf(" (%s); last: %s: %s", by.c_str(),
                daemon::to_string(dds::checked_from_wire<daemon::RejectReason>(s.last_reject_reason, "Status.last_reject_reason"))
                    .data(),
                s.last_reject_detail);
  std::printf("\n");
}

/// Runs `body` and maps the client's failures to exit codes.
template <typename F>
void run_client(F&& body) {
  try {
    body();
  } catch (const Rejected& e) {
    std::fprintf(stderr, "pvcgel: %s\n", e.what());
    throw CLI::RuntimeError(kExitRejected);
  } catch (const NoDaemon& e) {
    std::fprintf(stderr, "pvcgel: %s\n", e.what());
    throw CLI::RuntimeError(kExitNoDaemon);
  }
}

struct SendArgs {
  std::string kind, csv;
  std::vector<double> values;
  double blend_s = 2.0, duration_s = 0.0, at_s = -1.0, period_s = 0.0;
  bool append = false, voltage = false, start = false;
};

/// Arm and start when the rig is not running yet.
/// The states a command leads to (FAULT too: the loop may fault meanwhile).
bool reached(CommandKind kind, LoopState s) {
  switch (kind) {
    case CommandKind::arm: return s == LoopState::armed || s == LoopState::fault;
    case CommandKind::start: return s == LoopState::running || s == LoopState::ramp_down || s == LoopState::fault;
    case CommandKind::stop: return s != LoopState::running && s != LoopState::armed;
    case CommandKind::reset: return s != LoopState::fault;
    default: return true;
  }
}

void ensure_running(DdsClient& c) {
  const auto state = state_of(c.status());
  if (state == daemon::LoopState::running) return;
  if (state == daemon::LoopState::disabled) c.command(CommandKind::arm);
  c.command(CommandKind::start);
}

pvcgel_v1_Trajectory make_trajectory(const SendArgs& a, SegmentKind kind, std::vector<double>& values) {
  pvcgel_v1_Trajectory t{};
  t.target = to_wire(a.voltage ? daemon::LoopTarget::voltage : daemon::LoopTarget::displacement);
  t.kind = to_wire(kind);
  t.timing = a.append ? 1 : 0;
  t.start_time_s = a.at_s;
  t.duration_s = a.duration_s;
  t.blend_s = a.blend_s;
  t.values._buffer = values.data();
  t.values._length = static_cast<uint32_t>(values.size());
  t.values._maximum = t.values._length;
  t.values._release = false;
  return t;
}

/// Reads `t_s,r` rows (a header line and `#` lines are skipped) and checks the spacing is uniform.
std::vector<double> read_setpoint_csv(const std::string& path, double& period_s) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read '" + path + "'");
  std::vector<double> t, r;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    std::string a, b;
    if (!std::getline(ls, a, ',') || !std::getline(ls, b, ','))
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": expected two columns t_s,setpoint");
    char* end = nullptr;
    const double tv = std::strtod(a.c_str(), &end);
    if (end == a.c_str()) {
      if (t.empty()) continue;  // header
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": '" + a + "' is not a number");
    }
    const double rv = std::strtod(b.c_str(), &end);
    if (end == b.c_str() || !std::isfinite(rv) || !std::isfinite(tv))
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": '" + b + "' is not a finite number");
    if (!t.empty() && !(tv > t.back()))
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": time " + a + " does not increase");
    t.push_back(tv);
    r.push_back(rv);
  }
  if (r.size() < 2) throw std::runtime_error(path + ": needs at least two rows t_s,setpoint");
  period_s = (t.back() - t.front()) / static_cast<double>(t.size() - 1);
  for (std::size_t i = 1; i < t.size(); ++i)
    if (std::abs(t[i] - t[i - 1] - period_s) > 1e-3 * period_s + 1e-9)
      throw std::runtime_error(path + ":" + std::to_string(i + 1) + ": sample spacing " + format("%g", t[i] - t[i - 1]) +
                               " s differs from the mean " + format("%g", period_s) + " s (uniform sampling required)");
  return r;
}

/// One of the paper's references (control::paper_reference, by its canonical name) as a segment: y_r1 a sine,
/// y_r2 a multisine.
std::pair<SegmentKind, std::vector<double>> paper_segment(const std::string& name) {
  const auto& names = control::kPaperReferenceNames;
  const auto ref = std::find(names.begin(), names.end(), name) != names.end() ? control::paper_reference(name) : std::nullopt;
  if (!ref) throw std::runtime_error("send paper takes 0.1Hz, 0.5Hz, 1Hz or multi, not '" + name + "'");
  return {ref->n_tones == 1 ? SegmentKind::sine : SegmentKind::multisine, control::multisine_segment_values(*ref)};
}

/// The segment of `send KIND VALUES...` (every kind but csv): its kind and values, a sine's phase
/// defaulted to 0, a multiharmonic's pairs expanded with phases 0. Throws naming the form expected.
std::pair<SegmentKind, std::vector<double>> segment_of(const SendArgs& a) {
  std::vector<double> v = a.values;
  const auto need = [&](std::size_t n, const char* form) {
    if (v.size() != n) throw std::runtime_error("send " + a.kind + " takes " + form);
  };
  if (a.kind == "hold") {
    need(1, "LEVEL");
    return {SegmentKind::hold, v};
  }
  if (a.kind == "ramp") {
    need(2, "FROM TO (and --duration S)");
    return {SegmentKind::ramp, v};
  }
  if (a.kind == "sine") {
    if (v.size() == 3) v.push_back(0.0);
    need(4, "OFFSET AMPLITUDE FREQ_HZ [PHASE_RAD]");
    return {SegmentKind::sine, v};
  }
  if (a.kind == "multiharmonic") {
    if (v.size() < 3 || v.size() % 2 == 0) throw std::runtime_error("send multiharmonic takes OFFSET A1 F1 [A2 F2 ...]");
    std::vector<double> w{v[0]};
    for (std::size_t i = 1; i + 1 < v.size(); i += 2) w.insert(w.end(), {v[i], v[i + 1], 0.0});
    return {SegmentKind::multisine, w};
  }
  if (a.kind == "paper") return paper_segment(a.csv);
  throw std::runtime_error("unknown trajectory kind '" + a.kind + "'");
}

/// `send csv FILE`: the samples in chunks of 1024, the first blended (and timed) as asked, the rest
/// appended; a busy daemon (it already holds max_lead_s of setpoints) is waited for, a refusal ends it.
void send_csv(DdsClient& c, const SendArgs& a) {
  double period = 0.0;
  const std::vector<double> all = read_setpoint_csv(a.csv, period);
  const double loop_period = c.status().period_s;
  if (period < loop_period * 0.999)
    throw std::runtime_error(a.csv + ": sample period " + format("%g", period) + " s is shorter than the loop's " +
                             format("%g", loop_period) + " s");
  constexpr std::size_t kChunk = 1024;
  std::size_t sent = 0;
  while (sent < all.size() && !g_interrupted) {
    const bool first = sent == 0;
    std::vector<double> chunk(all.begin() + static_cast<std::ptrdiff_t>(sent),
                              all.begin() + static_cast<std::ptrdiff_t>(std::min(all.size(), sent + kChunk)));
    SendArgs piece = a;
    piece.append = !first || a.append;
    piece.blend_s = first ? a.blend_s : 0.0;
    piece.at_s = first ? a.at_s : -1.0;
    auto t = make_trajectory(piece, SegmentKind::samples, chunk);
    t.period_s = period;
    const Reply r = c.send(t, false);
    if (r.reason == daemon::RejectReason::busy) {
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
      continue;
    }
    if (!r.accepted)
      throw Rejected("trajectory chunk " + std::to_string(sent / kChunk + 1) + " rejected by rig '" + c.options().rig +
                         "': " + std::string(daemon::to_string(r.reason)) + ": " + r.detail,
                     r);
    sent += chunk.size();
    std::fprintf(stderr, "\rpvcgel send: %zu / %zu samples queued", sent, all.size());
  }
  std::fprintf(stderr, "\n");
}

/// `send KIND VALUES...` (every kind but csv) as its segment: one trajectory, refused or accepted.
void send_segment(DdsClient& c, const SendArgs& a, std::pair<SegmentKind, std::vector<double>> segment) {
  auto t = make_trajectory(a, segment.first, segment.second);  // borrows the values
  c.send(t);
  std::printf("rig %s: %s accepted\n", c.options().rig.c_str(), a.kind.c_str());
}

void watch(DdsClient& c, double duration_s) {
  c.connect();
  std::signal(SIGINT, [](int) { g_interrupted = 1; });
  const bool tty = isatty(STDOUT_FILENO) != 0;
  const auto start = std::chrono::steady_clock::now();
  auto last_print = start - std::chrono::seconds(1);
  pvcgel_v1_Telemetry last{};
  bool have = false;
  double err_sq = 0.0;
  std::uint64_t n = 0, first_seq = 0, last_seq = 0;
  while (!g_interrupted) {
    for (const auto& t : c.take_telemetry()) {
      if (!have) first_seq = t.seq;
      last = t;
      last_seq = t.seq;
      have = true;
      if (from_wire<LoopState>(t.state) == LoopState::running && std::isfinite(t.e_um)) {
        err_sq += t.e_um * t.e_um;
        ++n;
      }
    }
    const auto now = std::chrono::steady_clock::now();
    if (now - last_print >= std::chrono::milliseconds(tty ? 100 : 1000)) {
      const auto& s = c.status();
      const std::string line =
          have ? format("t %9.3f s  r %8.3f  y %8.3f um  u %7.1f V  e %+7.3f um  rms(e) %.3f um  | %s", last.t_s, last.r_um,
                        last.y_um, last.u_V, last.e_um, n ? std::sqrt(err_sq / static_cast<double>(n)) : 0.0,
                        state_line(s).c_str())
               : "(no telemetry yet) | " + state_line(s);
      std::printf(tty ? "\r\033[K%s" : "%s\n", line.c_str());
      std::fflush(stdout);
      last_print = now;
    }
    if (duration_s > 0 && now - start > std::chrono::duration<double>(duration_s)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (tty) std::printf("\n");
  std::printf("watched %llu telemetry samples (seq %llu..%llu)\n",
              static_cast<unsigned long long>(have ? last_seq - first_seq + 1 : 0),
              static_cast<unsigned long long>(first_seq), static_cast<unsigned long long>(last_seq));
}

/// arm, start, stop, reset, clear: one command each, then the state it led to.
void add_state_commands(CLI::App& app) {
  const auto simple = [&app](const char* name, const char* help, CommandKind kind) {
    auto opt = std::make_shared<ClientOptions>();
    auto* cmd = app.add_subcommand(name, help);
    add_client_options(*cmd, *opt);
    cmd->callback([opt, kind, name] {
      run_client([&] {
        DdsClient c(*opt);
        c.connect();
        if (kind == CommandKind::start && state_of(c.status()) == LoopState::running) {
          std::printf("rig %s: already RUNNING; start not sent\n", opt->rig.c_str());
          return;
        }
        if (kind == CommandKind::start) {
          ensure_running(c);
        } else {
          c.command(kind);
        }
        // Print the state the command led to, not the Status that was current when the reply came.
        const auto& s = c.wait_status([kind](const pvcgel_v1_Status& st) { return reached(kind, state_of(st)); },
                                      opt->wait_s);
        std::printf("rig %s: %s accepted; now %s\n", opt->rig.c_str(), name, state_line(s).c_str());
      });
    });
  };
  simple("arm", "Arm the rig: high voltage on at 0 V (DISABLED -> ARMED)", CommandKind::arm);
  simple("start", "Arm if needed and start closed-loop control (ARMED -> RUNNING; holds position until setpoints arrive)",
         CommandKind::start);
  simple("stop", "Ramp the output to 0 V and disable high voltage (the daemon keeps running)", CommandKind::stop);
  simple("reset", "Clear a fault (FAULT -> DISABLED)", CommandKind::reset);
  simple("clear", "Drop every queued setpoint segment (the current setpoint is held)", CommandKind::clear);
}

/// status and watch: read-only.
void add_view_commands(CLI::App& app) {
  {
    auto opt = std::make_shared<ClientOptions>();
    auto* cmd = app.add_subcommand("status", "Print the rig's state, loop statistics and input counters");
    add_client_options(*cmd, *opt);
    cmd->callback([opt] {
      run_client([&] {
        DdsClient c(*opt);
        print_status(c.fresh_status());
      });
    });
  }
  {
    auto opt = std::make_shared<ClientOptions>();
    auto duration = std::make_shared<double>(0.0);
    auto* cmd = app.add_subcommand("watch", "Live view of the rig's telemetry and state (Ctrl-C to leave)");
    add_client_options(*cmd, *opt);
    cmd->add_option("--duration", *duration, "leave after this many seconds (0: until Ctrl-C)");
    cmd->callback([opt, duration] {
      run_client([&] {
        DdsClient c(*opt, true, false);
        watch(c, *duration);
      });
    });
  }
}

/// mode and target: a command with an argument from the enum's names.
void add_argument_commands(CLI::App& app) {
  {
    auto opt = std::make_shared<ClientOptions>();
    auto name = std::make_shared<std::string>();
    auto* cmd = app.add_subcommand("mode", "Switch the controller mode (bumpless, any state)");
    add_client_options(*cmd, *opt);
    cmd->add_option("NAME", *name, "pid | inverse_pid | inverse_pid_dob | inverse_pid_dob_ff")->required();
    cmd->callback([opt, name] {
      const auto m = control::parse_mode(*name);
      if (!m) throw CLI::ValidationError("NAME", "'" + *name + "' is not pid, inverse_pid, inverse_pid_dob or inverse_pid_dob_ff");
      run_client([&] {
        DdsClient c(*opt);
        c.command(CommandKind::set_mode, to_wire(*m));
        std::printf("rig %s: mode %s accepted\n", opt->rig.c_str(), name->c_str());
      });
    });
  }
  {
    auto opt = std::make_shared<ClientOptions>();
    auto name = std::make_shared<std::string>();
    auto* cmd = app.add_subcommand("target", "Closed-loop displacement setpoints or open-loop voltage setpoints "
                                             "(identification); not while RUNNING");
    add_client_options(*cmd, *opt);
    cmd->add_option("TARGET", *name, "displacement | voltage")
        ->required()
        ->check(CLI::IsMember(std::vector<std::string>(daemon::kLoopTargetNames.names().begin(),
                                                       daemon::kLoopTargetNames.names().end())));
    cmd->callback([opt, name] {
      run_client([&] {
        DdsClient c(*opt);
        c.command(CommandKind::set_target, to_wire(*parse_enum<daemon::LoopTarget>(*name)));  // checked by IsMember
        std::printf("rig %s: target %s accepted\n", opt->rig.c_str(), name->c_str());
      });
    });
  }
}

void add_send_command(CLI::App& app) {
  auto opt = std::make_shared<ClientOptions>();
  auto args = std::make_shared<SendArgs>();
  auto* cmd = app.add_subcommand("send", "Send setpoints: hold LEVEL | ramp FROM TO | sine OFFSET AMP FREQ [PHASE] | "
                                         "multiharmonic OFFSET A1 F1 [A2 F2 ...] | paper 0.1Hz|0.5Hz|1Hz|multi | csv FILE");
  add_client_options(*cmd, *opt);
  cmd->add_option("KIND", args->kind, "hold | ramp | sine | multiharmonic | paper | csv")
      ->required()
      ->check(CLI::IsMember({"hold", "ramp", "sine", "multiharmonic", "paper", "csv"}));
  auto words = std::make_shared<std::vector<std::string>>();
  cmd->add_option("VALUES", *words, "numbers (um, or V with --voltage), the paper reference name, or the CSV file");
  cmd->add_option("--blend", args->blend_s, "raised-cosine blend from the setpoint in force (s)")->capture_default_str();
  cmd->add_option("--duration", args->duration_s, "segment length (s); 0: until replaced (ramp: ramp time)");
  cmd->add_option("--at", args->at_s, "loop time (s, as Telemetry t_s) to start at; default: now");
  cmd->add_flag("--append", args->append, "start where the queued setpoints end instead of replacing them");
  cmd->add_flag("--voltage", args->voltage, "voltage setpoints (open-loop target; see `pvcgel target`)");
  cmd->add_flag("--start", args->start, "arm and start the rig first if it is not running");
  cmd->callback([opt, args, words] {
    SendArgs a = *args;
    if (a.kind == "csv" || a.kind == "paper") {
      if (words->size() != 1) throw CLI::ValidationError("VALUES", "send " + a.kind + " takes exactly one argument");
      a.csv = (*words)[0];
    } else {
      for (const auto& w : *words) {
        char* end = nullptr;
        const double x = std::strtod(w.c_str(), &end);
        if (end == w.c_str() || *end != '\0') throw CLI::ValidationError("VALUES", "'" + w + "' is not a number");
        a.values.push_back(x);
      }
    }
    // A segment that does not fit its kind is a command-line mistake, reported before any rig is reached.
    std::optional<std::pair<SegmentKind, std::vector<double>>> segment;
    if (a.kind != "csv") try {
        segment = segment_of(a);
      } catch (const std::runtime_error& e) {
        throw CLI::ValidationError("VALUES", e.what());
      }
    run_client([&] {
      DdsClient c(*opt);
      c.connect();
      if (a.start) ensure_running(c);
      if (segment)
        send_segment(c, a, *std::move(segment));
      else
        send_csv(c, a);
    });
  });
}

}  // namespace

void add_client_commands(CLI::App& app) {
  add_state_commands(app);
  add_view_commands(app);
  add_argument_commands(app);
  add_send_command(app);
}

}  // namespace pvcgel::tools
