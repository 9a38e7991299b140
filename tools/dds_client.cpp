#include "tools/dds_client.hpp"

#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <thread>

#include "daemon/dds/dds_messages.hpp"
#include "tools/text_output.hpp"

namespace pvcgel::tools {

namespace {

using Clock = std::chrono::steady_clock;

std::int64_t realtime_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

bool same_guid(const dds_guid_t& a, const dds_guid_t& b) { return std::memcmp(a.v, b.v, sizeof a.v) == 0; }

}  // namespace

daemon::LoopState state_of(const pvcgel_v1_Status& s) {
  return dds::checked_from_wire<daemon::LoopState>(s.state, "Status.state");
}
daemon::FaultReason fault_of(const pvcgel_v1_Status& s) {
  return dds::checked_from_wire<daemon::FaultReason>(s.fault, "Status.fault");
}

NoDaemon no_daemon_error(const std::string& rig, int domain, double wait_s, const std::vector<std::string>& rigs_seen,
                         const std::string& also_needs) {
  if (rigs_seen.empty())
    return NoDaemon("no daemon found within " + format("%g", wait_s) + " s on domain " + std::to_string(domain) +
                    " (is pvcgeld running with [dds] enabled" + also_needs + ", on the same DDS configuration?)");
  std::string seen;
  for (const auto& r : rigs_seen) seen += (seen.empty() ? "" : ", ") + r;
  return NoDaemon("rig '" + rig + "' unknown; rigs seen: " + seen);
}

dds::Entity make_client_participant(const ClientOptions& o) {
  if (o.dds_config.empty())
    throw std::runtime_error("no DDS configuration: pass --dds-config FILE or set PVCGEL_DDS_CONFIG (on one PC: "
                             "config/cyclonedds-loopback.xml)");
  dds::DdsSettings s;
  s.domain = o.domain;
  s.config_path = o.dds_config;
  s.rig_id = o.rig;
  return dds::make_participant(s);
}

void add_client_options(CLI::App& cmd, ClientOptions& o) {
  if (const char* env = std::getenv("PVCGEL_DDS_CONFIG")) o.dds_config = env;
  cmd.add_option("--rig", o.rig, "rig id (the daemon's [dds] rig_id)")->capture_default_str();
  cmd.add_option("--domain", o.domain, "DDS domain")->capture_default_str();
  cmd.add_option("--dds-config", o.dds_config,
                 "Cyclone DDS XML configuration (default $PVCGEL_DDS_CONFIG; config/cyclonedds-loopback.xml on one PC)")
      ->capture_default_str();
  cmd.add_option("--wait", o.wait_s, "seconds to look for the daemon and to wait for each reply")->capture_default_str();
}

DdsClient::DdsClient(const ClientOptions& o, bool telemetry, bool reliable_telemetry) : opt_(o) {
  char host[64] = "host";
  gethostname(host, sizeof host - 1);
  client_id_ = std::string("pvcgel@") + host;
  client_id_ = client_id_.substr(0, 24) + ":" + std::to_string(getpid());
  // Sequence numbers start from the clock so a restarted client never reuses a recent one.
  next_seq_ = static_cast<std::uint64_t>(realtime_ns() / 1000);

  participant_ = make_client_participant(opt_);
  const dds_entity_t p = participant_.get();
  reply_topic_ = dds::make_topic(p, dds::Topic::command_reply);
  status_topic_ = dds::make_topic(p, dds::Topic::status);
  reply_reader_ = dds::Entity(dds_create_reader(p, reply_topic_.get(), dds::reply_qos().get(), nullptr), "CommandReply reader");
  status_reader_ = dds::Entity(dds_create_reader(p, status_topic_.get(), dds::status_qos().get(), nullptr), "Status reader");
  if (telemetry) {
    telemetry_topic_ = dds::make_topic(p, dds::Topic::telemetry);
    telemetry_reader_ = dds::Entity(
        dds_create_reader(p, telemetry_topic_.get(), dds::telemetry_qos(reliable_telemetry).get(), nullptr),
        "Telemetry reader");
  }
}

void DdsClient::poll_status() {
  void* samples[8] = {};
  dds_sample_info_t infos[8];
  for (;;) {
    const int n = dds_take(status_reader_.get(), samples, infos, 8, 8);
    if (n <= 0) return;
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* s = static_cast<const pvcgel_v1_Status*>(samples[i]);
      if (opt_.rig != s->rig_id) {
        if (std::find(other_rigs_.begin(), other_rigs_.end(), s->rig_id) == other_rigs_.end())
          other_rigs_.emplace_back(s->rig_id);
        continue;
      }
      if (auto* ep = dds_get_matched_publication_data(status_reader_.get(), infos[i].publication_handle)) {
        if (!status_) daemon_participant_ = ep->participant_key;
        else if (!same_guid(ep->participant_key, daemon_participant_)) duplicate_rig_ = true;
        dds_builtintopic_free_endpoint(ep);
      }
      status_ = *s;
    }
    dds_return_loan(status_reader_.get(), samples, n);
  }
}

bool DdsClient::matched_daemon(dds_entity_t endpoint, bool is_writer) {
  dds_instance_handle_t handles[64];
  const int n = is_writer ? dds_get_matched_subscriptions(endpoint, handles, 64)
                          : dds_get_matched_publications(endpoint, handles, 64);
  for (int i = 0; i < std::min(n, 64); ++i) {
    auto* ep = is_writer ? dds_get_matched_subscription_data(endpoint, handles[i])
                         : dds_get_matched_publication_data(endpoint, handles[i]);
    if (!ep) continue;
    const bool same = same_guid(ep->participant_key, daemon_participant_);
    dds_builtintopic_free_endpoint(ep);
    if (same) return true;
  }
  return false;
}

const pvcgel_v1_Status& DdsClient::connect() {
  const auto deadline = Clock::now() + std::chrono::duration<double>(opt_.wait_s);
  while (!status_) {
    poll_status();
    if (status_) break;
    if (Clock::now() > deadline) throw no_daemon_error(opt_.rig, opt_.domain, opt_.wait_s, other_rigs_);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  // Two daemons configured with one rig id would both obey every command: refuse to talk to either.
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  poll_status();
  if (duplicate_rig_)
    throw std::runtime_error("two daemons on domain " + std::to_string(opt_.domain) + " claim rig '" + opt_.rig +
                             "': give each rig its own [dds] rig_id");
  // A reply or sample sent before the daemon's writer matched our reader would be lost.
  while (!(matched_daemon(reply_reader_.get(), false) &&
           (telemetry_reader_.get() == 0 || matched_daemon(telemetry_reader_.get(), false)))) {
    if (Clock::now() > deadline)
      throw std::runtime_error("found rig '" + opt_.rig + "' but its command endpoints did not match within " +
                               format("%g", opt_.wait_s) + " s (QoS or version mismatch?)");
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return *status_;
}

const pvcgel_v1_Status& DdsClient::fresh_status() {
  const double t0 = connect().t_s;
  // The sample a new reader gets first may predate the match; the daemon
  // publishes at least every 0.5 s, so wait for the next one.
  const auto deadline = Clock::now() + std::chrono::milliseconds(1500);
  while (status_->t_s == t0 && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    poll_status();
  }
  return *status_;
}

const pvcgel_v1_Status& DdsClient::wait_status(const std::function<bool(const pvcgel_v1_Status&)>& done,
                                                double timeout_s) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(timeout_s);
  poll_status();
  while (!done(*status_) && Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    poll_status();
  }
  return *status_;
}

void DdsClient::ensure_writers() {
  if (command_writer_.get() != 0) return;
  if (!status_) connect();
  // Created only when needed, so a read-only identity (DDS Security) can still watch and record.
  const dds_entity_t p = participant_.get();
  trajectory_topic_ = dds::make_topic(p, dds::Topic::trajectory);
  command_topic_ = dds::make_topic(p, dds::Topic::command);
  trajectory_writer_ = dds::Entity(dds_create_writer(p, trajectory_topic_.get(), dds::trajectory_qos(false).get(), nullptr),
                                   "Trajectory writer");
  command_writer_ = dds::Entity(dds_create_writer(p, command_topic_.get(), dds::command_qos(false).get(), nullptr),
                                "Command writer");
  // Reliable volatile: a sample written before the daemon's reader matched ours would be lost.
  const auto deadline = Clock::now() + std::chrono::duration<double>(opt_.wait_s);
  while (!(matched_daemon(command_writer_.get(), true) && matched_daemon(trajectory_writer_.get(), true))) {
    if (Clock::now() > deadline)
      throw std::runtime_error("rig '" + opt_.rig + "' did not accept our command endpoints within " +
                               format("%g", opt_.wait_s) + " s (QoS mismatch, or not permitted by DDS Security?)");
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

const pvcgel_v1_Status& DdsClient::status() {
  poll_status();
  if (!status_) return connect();
  return *status_;
}

std::uint64_t DdsClient::publish_command(daemon::CommandKind kind, std::uint8_t argument, std::uint64_t seq) {
  ensure_writers();
  pvcgel_v1_Command c{};
  dds::copy_bounded(c.rig_id, opt_.rig);
  dds::copy_bounded(c.client_id, client_id_);
  c.command_seq = seq != 0 ? seq : ++next_seq_;
  c.kind = to_wire(kind);
  c.argument = argument;
  if (const auto rc = dds_write(command_writer_.get(), &c); rc < 0)
    throw std::runtime_error(std::string("DDS write of a command failed: ") + dds_strretcode(rc));
  return c.command_seq;
}

std::uint64_t DdsClient::publish_trajectory(pvcgel_v1_Trajectory& t) {
  ensure_writers();
  dds::copy_bounded(t.rig_id, opt_.rig);
  dds::copy_bounded(t.client_id, client_id_);
  t.chunk_seq = ++next_seq_;
  t.publish_time_ns = realtime_ns();
  if (const auto rc = dds_write(trajectory_writer_.get(), &t); rc < 0)
    throw std::runtime_error(std::string("DDS write of a trajectory failed: ") + dds_strretcode(rc));
  return t.chunk_seq;
}

std::vector<pvcgel_v1_CommandReply> DdsClient::take_replies() {
  std::vector<pvcgel_v1_CommandReply> out;
  out.swap(stray_replies_);
  void* samples[64] = {};
  dds_sample_info_t infos[64];
  for (;;) {
    const int n = dds_take(reply_reader_.get(), samples, infos, 64, 64);
    if (n <= 0) break;
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* r = static_cast<const pvcgel_v1_CommandReply*>(samples[i]);
      if (opt_.rig == r->rig_id && client_id_ == r->client_id) out.push_back(*r);
    }
    dds_return_loan(reply_reader_.get(), samples, n);
  }
  return out;
}

Reply DdsClient::wait_reply(std::uint64_t seq, bool is_trajectory, const char* what, bool throw_on_reject,
                            const std::function<void()>& resend) {
  const auto deadline = Clock::now() + std::chrono::duration<double>(opt_.wait_s);
  auto next_resend = Clock::now() + std::chrono::seconds(1);
  for (;;) {
    if (resend && Clock::now() > next_resend) {
      // The daemon's reader may not have matched our writer yet when the sample
      // went out (discovery is not symmetric); the same seq again is answered once.
      resend();
      next_resend = Clock::now() + std::chrono::seconds(1);
    }
    auto replies = take_replies();
    for (auto it = replies.begin(); it != replies.end(); ++it) {
      if (it->seq != seq || it->is_trajectory != is_trajectory) continue;
      Reply r{it->accepted, dds::checked_from_wire<daemon::RejectReason>(it->reason, "CommandReply.reason"), it->detail};
      replies.erase(it);
      stray_replies_.insert(stray_replies_.end(), replies.begin(), replies.end());
      if (!r.accepted && throw_on_reject)
        throw Rejected(std::string(what) + " rejected by rig '" + opt_.rig + "': " +
                           std::string(daemon::to_string(r.reason)) + (r.detail.empty() ? "" : ": " + r.detail),
                       r);
      poll_status();
      return r;
    }
    stray_replies_.insert(stray_replies_.end(), replies.begin(), replies.end());
    if (stray_replies_.size() > 256) stray_replies_.erase(stray_replies_.begin(), stray_replies_.begin() + 128);
    if (Clock::now() > deadline)
      throw std::runtime_error(std::string("no reply to the ") + what + " from rig '" + opt_.rig + "' within " +
                               format("%g", opt_.wait_s) + " s (daemon busy or gone?)");
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
}

Reply DdsClient::command(daemon::CommandKind kind, std::uint8_t argument, bool throw_on_reject) {
  if (!status_) connect();
  const std::string what = "command '" + std::string(daemon::to_string(kind)) + "'";
  const std::uint64_t seq = publish_command(kind, argument);
  return wait_reply(seq, false, what.c_str(), throw_on_reject, [&] { publish_command(kind, argument, seq); });
}

Reply DdsClient::send(pvcgel_v1_Trajectory& t, bool throw_on_reject) {
  if (!status_) connect();
  const std::uint64_t seq = publish_trajectory(t);
  return wait_reply(seq, true, "trajectory", throw_on_reject, [&] { dds_write(trajectory_writer_.get(), &t); });
}

std::vector<pvcgel_v1_Telemetry> DdsClient::take_telemetry(int max) {
  std::vector<pvcgel_v1_Telemetry> out;
  if (telemetry_reader_.get() == 0) return out;
  void* samples[256] = {};
  dds_sample_info_t infos[256];
  while (static_cast<int>(out.size()) < max) {
    const int n = dds_take(telemetry_reader_.get(), samples, infos, 256, 256);
    if (n <= 0) break;
    for (int i = 0; i < n; ++i)
      if (infos[i].valid_data && opt_.rig == static_cast<const pvcgel_v1_Telemetry*>(samples[i])->rig_id)
        out.push_back(*static_cast<const pvcgel_v1_Telemetry*>(samples[i]));
    dds_return_loan(telemetry_reader_.get(), samples, n);
  }
  return out;
}

}  // namespace pvcgel::tools
