// A pvcgel client written with eProsima Fast DDS instead of Cyclone DDS, the
// stack of ROS 2's default middleware (rmw_fastrtps). Its types are generated
// at build time by fastddsgen from daemon/dds/pvcgel_v1.idl, the same file the
// daemon's Cyclone types come from; nothing here knows about Cyclone.
//
//   listen  record the daemon's telemetry for a while (CSV)
//   drive   arm and start (unless RUNNING), hold a level, play a sine, stop; telemetry to CSV,
//           every CommandReply and the last Status on stdout
//   echo    publish one Command and one Trajectory whose fields derive from
//           --seq, print every field of the Status and CommandReply received
//           (the test's Cyclone peer checks both directions field by field)
//
// Exit codes: 0 done, 1 DDS or protocol error (message on stderr), 2 usage.
#include <CLI/CLI.hpp>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <functional>
#include <iostream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "pvcgel_v1PubSubTypes.h"

namespace {

namespace fdds = eprosima::fastdds::dds;
namespace v1 = pvcgel::v1;
using Clock = std::chrono::steady_clock;

constexpr const char* kProfile = "pvcgel_loopback";

/// Command kinds and Telemetry states as documented in the IDL.
enum CommandKind : uint8_t { kArm = 1, kStart = 2, kStop = 3, kClear = 7 };
enum TrajectoryKind : uint8_t { kSamples = 0, kHold = 1, kSine = 3 };
constexpr uint8_t kStateRunning = 2;

struct Options {
  std::string profile_path;
  int domain = 0;
  std::string rig_id = "rig1";
  std::string client_id = "fastdds-interop";
  double wait_s = 10.0;
  std::string out_path;
  // listen
  double duration_s = 3.0;
  bool best_effort = false;
  // drive
  double level_um = 60.0;
  double blend_s = 1.0;
  double hold_s = 3.0;
  double sine_amplitude_um = 20.0;
  double sine_freq_Hz = 0.5;
  double sine_s = 4.0;
  // echo
  uint64_t seq = 1;
  std::vector<double> values;
};

[[noreturn]] void fail(const std::string& what) { throw std::runtime_error(what); }

/// Prints a double so that it reads back bit-exactly.
std::string exact(double x) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

/// A topic with its registered type, in the participant that owns both.
template <class PubSubType>
fdds::Topic* make_topic(fdds::DomainParticipant* p, const char* name) {
  fdds::TypeSupport type(new PubSubType());
  if (type.register_type(p) != ReturnCode_t::RETCODE_OK) fail(std::string("cannot register type for ") + name);
  fdds::Topic* t = p->create_topic(name, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
  if (t == nullptr) fail(std::string("cannot create topic ") + name);
  return t;
}

/// QoS as documented at each struct of the IDL (Fast DDS's defaults differ:
/// its writers default to transient-local, its readers to best-effort).
fdds::DataWriterQos writer_qos() {
  fdds::DataWriterQos q = fdds::DATAWRITER_QOS_DEFAULT;
  q.reliability().kind = fdds::RELIABLE_RELIABILITY_QOS;
  q.durability().kind = fdds::VOLATILE_DURABILITY_QOS;
  q.history().kind = fdds::KEEP_ALL_HISTORY_QOS;
  return q;
}

fdds::DataReaderQos reader_qos(bool transient_local, bool keep_all, int depth, bool reliable = true) {
  fdds::DataReaderQos q = fdds::DATAREADER_QOS_DEFAULT;
  q.reliability().kind = reliable ? fdds::RELIABLE_RELIABILITY_QOS : fdds::BEST_EFFORT_RELIABILITY_QOS;
  q.durability().kind = transient_local ? fdds::TRANSIENT_LOCAL_DURABILITY_QOS : fdds::VOLATILE_DURABILITY_QOS;
  q.history().kind = keep_all ? fdds::KEEP_ALL_HISTORY_QOS : fdds::KEEP_LAST_HISTORY_QOS;
  q.history().depth = depth;
  return q;
}

/// The profile must keep the participant on loopback: refuse anything that
/// would open the default transports or a multicast locator.
void check_loopback_profile(const std::string& path) {
  auto* factory = fdds::DomainParticipantFactory::get_instance();
  if (factory->load_XML_profiles_file(path) != ReturnCode_t::RETCODE_OK)
    fail("cannot load Fast DDS profile '" + path + "'");
  fdds::DomainParticipantQos q;
  if (factory->get_participant_qos_from_profile(kProfile, q) != ReturnCode_t::RETCODE_OK)
    fail("profile '" + std::string(kProfile) + "' not found in '" + path + "'");
  const auto& b = q.wire_protocol().builtin;
  if (q.transport().use_builtin_transports) fail(path + ": useBuiltinTransports must be false (loopback only)");
  if (q.transport().user_transports.empty()) fail(path + ": no user transport");
  if (b.metatrafficUnicastLocatorList.empty() || !b.metatrafficMulticastLocatorList.empty())
    fail(path + ": discovery must be unicast (metatrafficUnicastLocatorList set, no multicast list)");
  if (!q.wire_protocol().default_multicast_locator_list.empty()) fail(path + ": no default multicast locators allowed");
}

/// The participant, one topic per IDL struct, and the readers and writers a client needs.
class Client final {
 public:
  explicit Client(const Options& o) : o_(o) {
    check_loopback_profile(o.profile_path);
    auto* factory = fdds::DomainParticipantFactory::get_instance();
    participant_ = factory->create_participant_with_profile(static_cast<fdds::DomainId_t>(o.domain), kProfile);
    if (participant_ == nullptr) fail("cannot create the Fast DDS participant on domain " + std::to_string(o.domain));
    auto* telemetry = make_topic<v1::TelemetryPubSubType>(participant_, "pvcgel_v1_Telemetry");
    auto* trajectory = make_topic<v1::TrajectoryPubSubType>(participant_, "pvcgel_v1_Trajectory");
    auto* command = make_topic<v1::CommandPubSubType>(participant_, "pvcgel_v1_Command");
    auto* reply = make_topic<v1::CommandReplyPubSubType>(participant_, "pvcgel_v1_CommandReply");
    auto* status = make_topic<v1::StatusPubSubType>(participant_, "pvcgel_v1_Status");
    auto* sub = participant_->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
    auto* pub = participant_->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
    if (sub == nullptr || pub == nullptr) fail("cannot create publisher/subscriber");
    // Reliable keep-all for the daemon's reliable_telemetry writer; its
    // default best-effort writer matches only a best-effort reader (requested
    // > offered), which keeps the last 100 here so a slow take loses nothing.
    telemetry_ = o.best_effort ? sub->create_datareader(telemetry, reader_qos(false, false, 100, false))
                               : sub->create_datareader(telemetry, reader_qos(false, true, 1));
    reply_ = sub->create_datareader(reply, reader_qos(false, false, 64));
    status_ = sub->create_datareader(status, reader_qos(true, false, 1));
    trajectory_ = pub->create_datawriter(trajectory, writer_qos());
    command_ = pub->create_datawriter(command, writer_qos());
    if (!telemetry_ || !reply_ || !status_ || !trajectory_ || !command_) fail("cannot create readers/writers");
  }

  ~Client() {
    participant_->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant_);
  }
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  /// Called for every telemetry sample of our rig, in order.
  std::function<void(const v1::Telemetry&)> on_telemetry;
  /// Called for every reply addressed to this client.
  std::function<void(const v1::CommandReply&)> on_reply;
  /// Called for every status of our rig.
  std::function<void(const v1::Status&)> on_status;

  /// Takes whatever arrived, waiting up to `max_wait_s` for something new.
  void pump(double max_wait_s) {
    telemetry_->wait_for_unread_message(eprosima::fastrtps::Duration_t(max_wait_s));
    v1::Telemetry t;
    fdds::SampleInfo info;
    while (telemetry_->take_next_sample(&t, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      if (t.rig_id() != o_.rig_id.c_str()) {
        ++other_rig_samples_;
        continue;
      }
      ++telemetry_samples_;
      last_telemetry_ = t;
      if (on_telemetry) on_telemetry(t);
    }
    v1::CommandReply r;
    while (reply_->take_next_sample(&r, &info) == ReturnCode_t::RETCODE_OK)
      if (info.valid_data && r.rig_id() == o_.rig_id.c_str() && r.client_id() == o_.client_id.c_str()) {
        replies_.push_back(r);
        if (on_reply) on_reply(r);
      }
    v1::Status s;
    while (status_->take_next_sample(&s, &info) == ReturnCode_t::RETCODE_OK)
      if (info.valid_data && s.rig_id() == o_.rig_id.c_str()) {
        ++status_samples_;
        if (on_status) on_status(s);
      }
  }

  /// Pumps for `seconds`.
  void pump_for(double seconds) {
    const auto end = Clock::now() + std::chrono::duration<double>(seconds);
    while (Clock::now() < end) pump(0.01);
  }

  /// Pumps until `done()` or `timeout_s`; false on timeout.
  bool pump_until(const std::function<bool()>& done, double timeout_s) {
    const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
    while (!done()) {
      if (Clock::now() >= end) return false;
      pump(0.01);
    }
    return true;
  }

  /// Waits for the daemon: its telemetry, and readers on Command and
  /// Trajectory and a writer on CommandReply (so nothing we send is lost).
  void wait_for_daemon(bool need_command_path) {
    if (!pump_until([&] { return telemetry_samples_ > 0; }, o_.wait_s))
      fail("no telemetry from rig '" + o_.rig_id + "' within " + exact(o_.wait_s) + " s" +
           (other_rig_samples_ > 0 ? " (other rigs are publishing)"
            : o_.best_effort       ? ""
                                   : " (a reliable reader needs the daemon's dds.reliable_telemetry = true; else --best-effort)"));
    if (need_command_path) wait_for_matches(o_.wait_s, "the daemon");
  }

  /// Waits until our writers and the reply reader have a peer.
  void wait_for_matches(double timeout_s, const std::string& peer) {
    fdds::PublicationMatchedStatus pc, pt;
    fdds::SubscriptionMatchedStatus sr;
    const bool ok = pump_until(
        [&] {
          command_->get_publication_matched_status(pc);
          trajectory_->get_publication_matched_status(pt);
          reply_->get_subscription_matched_status(sr);
          return pc.current_count > 0 && pt.current_count > 0 && sr.current_count > 0;
        },
        timeout_s);
    if (!ok)
      fail(peer + " has no " +
           std::string(pc.current_count == 0   ? "Command reader"
                       : pt.current_count == 0 ? "Trajectory reader"
                                               : "CommandReply writer") +
           " (QoS mismatch, or the daemon's command path is not there)");
  }

  void send(v1::Command c) {
    c.rig_id(o_.rig_id);
    c.client_id(o_.client_id);
    if (!command_->write(&c)) fail("Command write failed");
  }

  void send(v1::Trajectory t) {
    t.rig_id(o_.rig_id);
    t.client_id(o_.client_id);
    t.publish_time_ns(t.publish_time_ns() != 0 ? t.publish_time_ns() : realtime_ns());
    if (!trajectory_->write(&t)) fail("Trajectory write failed");
  }

  /// Calls `send` until the daemon answers (seq, is_trajectory): again after
  /// each second without an answer, five times at most; throws when refused
  /// or unanswered. Why again: discovery is asynchronous, so our writer can
  /// match the daemon's volatile reader before that reader has matched our
  /// writer, and the reader drops (never delivers late) what arrives in
  /// between. Only the first exchange on each topic can fall into that window.
  v1::CommandReply request(const std::function<void()>& send, uint64_t seq, bool is_trajectory,
                           const std::string& what) {
    constexpr int kTries = 5;
    for (int attempt = 1; attempt <= kTries; ++attempt) {
      send();
      if (pump_until([&] { return first_reply(seq, is_trajectory) != nullptr; }, 1.0)) {
        const v1::CommandReply& r = *first_reply(seq, is_trajectory);
        if (!r.accepted())
          fail(what + " rejected: reason " + std::to_string(r.reason()) + " (" + r.detail().to_string() + ")");
        return r;
      }
      std::cout << "no reply to " << what << " within 1 s (try " << attempt << " of " << kTries << ")" << std::endl;
    }
    fail("no CommandReply for " + what + " within " + std::to_string(kTries) + " s");
  }

  /// The first reply to (seq, is_trajectory), or null.
  [[nodiscard]] const v1::CommandReply* first_reply(uint64_t seq, bool is_trajectory) const {
    for (const auto& r : replies_)
      if (r.seq() == seq && r.is_trajectory() == is_trajectory) return &r;
    return nullptr;
  }

  /// Replies received: commands accepted, chunks accepted, refusals (as the daemon counts them in Status).
  /// A resent request is answered again but counted once by the daemon (DdsBridge::is_resend): so here.
  [[nodiscard]] std::string reply_counts() const {
    uint64_t commands = 0, chunks = 0, rejected = 0;
    for (const auto& r : replies_)
      if (first_reply(r.seq(), r.is_trajectory()) == &r)
        (r.accepted() ? (r.is_trajectory() ? chunks : commands) : rejected) += 1;
    return "commands_accepted=" + std::to_string(commands) + " chunks_accepted=" + std::to_string(chunks) +
           " rejects_total=" + std::to_string(rejected);
  }

  static int64_t realtime_ns() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
  }

  [[nodiscard]] uint64_t telemetry_samples() const { return telemetry_samples_; }
  [[nodiscard]] uint64_t other_rig_samples() const { return other_rig_samples_; }
  [[nodiscard]] uint64_t status_samples() const { return status_samples_; }
  [[nodiscard]] const v1::Telemetry& last_telemetry() const { return last_telemetry_; }

 private:
  Options o_;
  fdds::DomainParticipant* participant_ = nullptr;
  fdds::DataReader* telemetry_ = nullptr;
  fdds::DataReader* reply_ = nullptr;
  fdds::DataReader* status_ = nullptr;
  fdds::DataWriter* trajectory_ = nullptr;
  fdds::DataWriter* command_ = nullptr;
  std::vector<v1::CommandReply> replies_;
  v1::Telemetry last_telemetry_;
  uint64_t telemetry_samples_ = 0;
  uint64_t other_rig_samples_ = 0;
  uint64_t status_samples_ = 0;
};

/// Telemetry rows, one per sample, in arrival order.
class TelemetryCsv final {
 public:
  explicit TelemetryCsv(const std::string& path) : out_(path) {
    if (!out_) fail("cannot write '" + path + "'");
    out_ << "seq,t_s,r_um,y_um,u_V,e_um,d_hat,latency_us,mode,state,fault,high_voltage,target,chunk_seq,stamp_ns\n";
  }
  void write(const v1::Telemetry& t) {
    out_ << t.seq() << ',' << exact(t.t_s()) << ',' << exact(t.r_um()) << ',' << exact(t.y_um()) << ','
         << exact(t.u_V()) << ',' << exact(t.e_um()) << ',' << exact(t.d_hat()) << ',' << t.latency_us() << ','
         << int(t.mode()) << ',' << int(t.state()) << ',' << int(t.fault()) << ',' << int(t.high_voltage()) << ','
         << int(t.target()) << ',' << t.chunk_seq() << ',' << t.stamp_ns() << '\n';
  }

 private:
  std::ofstream out_;
};

void print_reply(const v1::CommandReply& r) {
  std::cout << "reply rig_id=" << r.rig_id().to_string() << " client_id=" << r.client_id().to_string()
            << " seq=" << r.seq() << " is_trajectory=" << int(r.is_trajectory()) << " accepted=" << int(r.accepted())
            << " reason=" << int(r.reason()) << " detail=" << r.detail().to_string() << std::endl;
}

void print_status(const v1::Status& s) {
  std::cout << "status rig_id=" << s.rig_id().to_string() << " t_s=" << exact(s.t_s()) << " state=" << int(s.state())
            << " fault=" << int(s.fault()) << " mode=" << int(s.mode()) << " target=" << int(s.target())
            << " high_voltage=" << int(s.high_voltage()) << " period_s=" << exact(s.period_s())
            << " queued_until_s=" << exact(s.queued_until_s()) << " cycles=" << s.cycles()
            << " overruns=" << s.overruns() << " records_dropped=" << s.records_dropped()
            << " latency_p50_us=" << exact(s.latency_p50_us()) << " latency_p99_us=" << exact(s.latency_p99_us())
            << " latency_p999_us=" << exact(s.latency_p999_us()) << " latency_max_us=" << exact(s.latency_max_us())
            << " compute_p99_us=" << exact(s.compute_p99_us()) << " chunks_accepted=" << s.chunks_accepted()
            << " commands_accepted=" << s.commands_accepted() << " rejects_total=" << s.rejects_total()
            << " rejects_by_reason=";
  for (size_t i = 0; i < s.rejects_by_reason().size(); ++i) std::cout << (i ? "," : "") << s.rejects_by_reason()[i];
  std::cout << " last_reject_reason=" << int(s.last_reject_reason())
            << " last_reject_detail=" << s.last_reject_detail().to_string()
            << " config_hash=" << s.config_hash().to_string() << " version=" << s.version().to_string()
            << " hal_backend=" << s.hal_backend().to_string() << std::endl;
}

int run_listen(const Options& o) {
  Client c(o);
  TelemetryCsv csv(o.out_path);
  c.on_telemetry = [&](const v1::Telemetry& t) { csv.write(t); };
  c.wait_for_daemon(false);
  c.pump_for(o.duration_s);
  std::cout << "telemetry samples " << c.telemetry_samples() << ", other rigs " << c.other_rig_samples() << std::endl;
  return 0;
}

v1::Command command(uint64_t seq, uint8_t kind, uint8_t argument = 0) {
  v1::Command c;
  c.command_seq(seq);
  c.kind(kind);
  c.argument(argument);
  return c;
}

/// A segment that starts at the next cycle, replacing what is queued.
v1::Trajectory segment(uint64_t chunk_seq, uint8_t kind, std::vector<double> values, double blend_s) {
  v1::Trajectory t;
  t.chunk_seq(chunk_seq);
  t.target(0);
  t.kind(kind);
  t.timing(0);
  t.start_time_s(-1.0);
  t.duration_s(0.0);
  t.blend_s(blend_s);
  t.values(std::move(values));
  return t;
}

int run_drive(const Options& o) {
  Client c(o);
  TelemetryCsv csv(o.out_path);
  c.on_telemetry = [&](const v1::Telemetry& t) { csv.write(t); };
  c.on_reply = print_reply;
  std::optional<v1::Status> last_status;
  c.on_status = [&](const v1::Status& s) { last_status = s; };
  c.wait_for_daemon(true);

  uint64_t seq = 0;
  auto execute = [&](uint8_t kind, const char* what) {
    const v1::Command cmd = command(++seq, kind);
    c.request([&] { c.send(cmd); }, seq, false, what);
  };
  auto play = [&](const v1::Trajectory& t, const char* what) {
    c.request([&] { c.send(t); }, t.chunk_seq(), true, what);
  };
  if (c.last_telemetry().state() == kStateRunning) {
    std::cout << "rig already RUNNING: arm and start skipped" << std::endl;
  } else {
    execute(kArm, "arm");
    execute(kStart, "start");
  }
  if (!c.pump_until([&] { return c.last_telemetry().state() == kStateRunning; }, 5.0))
    fail("rig not RUNNING 5 s after an accepted start");

  // Chunk numbers: 1 the hold, 2 the sine (the telemetry echoes them).
  std::cout << "sending chunk=1 kind=hold level_um=" << exact(o.level_um) << " blend_s=" << exact(o.blend_s)
            << " at_t_s=" << exact(c.last_telemetry().t_s()) << std::endl;
  play(segment(1, kHold, {o.level_um}, o.blend_s), "hold trajectory");
  c.pump_for(o.hold_s);

  // The sine starts at the hold level with zero phase: no step.
  std::cout << "sending chunk=2 kind=sine offset_um=" << exact(o.level_um) << " amplitude_um="
            << exact(o.sine_amplitude_um) << " freq_Hz=" << exact(o.sine_freq_Hz)
            << " at_t_s=" << exact(c.last_telemetry().t_s()) << std::endl;
  play(segment(2, kSine, {o.level_um, o.sine_amplitude_um, o.sine_freq_Hz, 0.0}, 0.0), "sine trajectory");
  c.pump_for(o.sine_s);

  execute(kStop, "stop");
  c.pump_for(0.3);
  if (last_status) print_status(*last_status);
  std::cout << "replies " << c.reply_counts() << std::endl;
  std::cout << "telemetry samples " << c.telemetry_samples() << ", other rigs " << c.other_rig_samples()
            << ", status samples " << c.status_samples() << std::endl;
  return 0;
}

int run_echo(const Options& o) {
  Client c(o);
  bool got_status = false, got_reply = false;
  c.on_status = [&](const v1::Status& s) {
    print_status(s);
    got_status = true;
  };
  c.on_reply = [&](const v1::CommandReply& r) {
    print_reply(r);
    got_reply = true;
  };
  c.wait_for_matches(o.wait_s, "the peer");
  // Field values derive from --seq (the peer checks them by the same rule).
  const auto s = static_cast<double>(o.seq);
  const v1::Command cmd = command(o.seq + 1, kClear, 255);
  v1::Trajectory t;
  t.chunk_seq(o.seq);
  t.publish_time_ns(-static_cast<int64_t>(o.seq));
  t.target(1);
  t.kind(kSamples);
  t.timing(1);
  t.start_time_s(s + 0.5);
  t.period_s(0.002);
  t.duration_s(0.25);
  t.blend_s(0.125);
  t.values(o.values);
  // Sent again each second until the peer answers (see Client::request); the peer reads the first.
  const auto deadline = Clock::now() + std::chrono::duration<double>(o.wait_s);
  while (!got_reply && Clock::now() < deadline) {
    c.send(cmd);
    c.send(t);
    c.pump_until([&] { return got_reply; }, 1.0);
  }
  const double left_s = std::chrono::duration<double>(deadline - Clock::now()).count();
  if (!c.pump_until([&] { return got_status && got_reply; }, std::max(0.0, left_s)))
    fail(std::string("no ") + (got_reply ? "Status" : "CommandReply") + " within " + exact(o.wait_s) + " s");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Fast DDS pvcgel client (interoperability test)"};
  Options o;
  app.add_option("--profile", o.profile_path, "Fast DDS XML with the loopback profile 'pvcgel_loopback'")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--domain", o.domain, "DDS domain")->check(CLI::Range(0, 232));
  app.add_option("--rig", o.rig_id, "rig id");
  app.add_option("--client-id", o.client_id, "client id (replies carry it back)");
  app.add_option("--wait", o.wait_s, "seconds to wait for the peer");
  app.require_subcommand(1);
  auto* listen = app.add_subcommand("listen", "record telemetry");
  listen->add_option("--out", o.out_path, "telemetry CSV")->required();
  listen->add_option("--duration", o.duration_s, "seconds after the first sample");
  listen->add_flag("--best-effort", o.best_effort, "best-effort reader (the daemon's default telemetry QoS)");
  auto* drive = app.add_subcommand("drive", "arm, start, hold, sine, stop");
  drive->add_option("--out", o.out_path, "telemetry CSV")->required();
  drive->add_option("--level", o.level_um, "hold level and sine offset (um)");
  drive->add_option("--blend", o.blend_s, "blend into the hold (s)");
  drive->add_option("--hold", o.hold_s, "seconds of hold");
  drive->add_option("--amplitude", o.sine_amplitude_um, "sine amplitude (um)");
  drive->add_option("--freq", o.sine_freq_Hz, "sine frequency (Hz)");
  drive->add_option("--sine", o.sine_s, "seconds of sine");
  auto* echo = app.add_subcommand("echo", "send one Command and Trajectory, print Status and CommandReply");
  echo->add_option("--seq", o.seq, "chunk_seq (command_seq = seq + 1); other fields derive from it")->required();
  echo->add_option("--values", o.values, "Trajectory.values")->delimiter(',');
  CLI11_PARSE(app, argc, argv);
  try {
    if (*listen) return run_listen(o);
    if (*drive) return run_drive(o);
    return run_echo(o);
  } catch (const std::exception& e) {
    std::cerr << "fastdds_client: " << e.what() << std::endl;
    return 1;
  }
}
