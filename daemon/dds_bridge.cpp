#include "daemon/dds_bridge.hpp"

#include <pthread.h>
#include <sched.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <vector>

#include "daemon/control_loop.hpp"
#include "daemon/dds/dds_messages.hpp"

namespace pvcgel::daemon {

namespace {

double steady_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string detail_for_loop_refusal(RejectReason r, LoopState state, FaultReason cause) {
  const std::string in_state = " (loop state " + std::string(to_string(state)) + ")";
  switch (r) {
    case RejectReason::illegal_in_state:
      if (cause != FaultReason::none)
        return "not allowed now" + in_state + ": the fault's cause is still present: " + std::string(to_string(cause));
      return "not allowed now" + in_state;
    case RejectReason::step_too_large:
      return "the first setpoint steps from the one in force beyond the limit; send a blend_s long enough" + in_state;
    case RejectReason::queue_full: return "the loop's setpoint queue is full" + in_state;
    case RejectReason::target_mismatch: return "the loop's target changed before the chunk was applied" + in_state;
    default: return std::string(to_string(r)) + in_state;
  }
}

constexpr int kBatch = 32;

}  // namespace

DdsBridge::DdsBridge(const dds::DdsSettings& settings, const SetpointLimits& limits, LoopIo& io,
                     const LoopStatistics& stats, DaemonIdentity identity)
    : settings_(settings), limits_(limits), io_(io), stats_(stats), identity_(std::move(identity)) {
  participant_ = dds::make_participant(settings_);
  const dds_entity_t p = participant_.get();
  telemetry_ = std::make_unique<TelemetryPublisher>(p, settings_);
  trajectory_topic_ = dds::make_topic(p, dds::Topic::trajectory);
  command_topic_ = dds::make_topic(p, dds::Topic::command);
  reply_topic_ = dds::make_topic(p, dds::Topic::command_reply);
  status_topic_ = dds::make_topic(p, dds::Topic::status);
  trajectory_reader_ = dds::Entity(dds_create_reader(p, trajectory_topic_.get(), dds::trajectory_qos(true).get(), nullptr),
                                   "Trajectory reader");
  command_reader_ = dds::Entity(dds_create_reader(p, command_topic_.get(), dds::command_qos(true).get(), nullptr),
                                "Command reader");
  reply_writer_ = dds::Entity(dds_create_writer(p, reply_topic_.get(), dds::reply_qos().get(), nullptr), "CommandReply writer");
  status_writer_ = dds::Entity(dds_create_writer(p, status_topic_.get(), dds::status_qos().get(), nullptr), "Status writer");
  waitset_ = dds::Entity(dds_create_waitset(p), "waitset");
  for (const auto r : {trajectory_reader_.get(), command_reader_.get()}) {
    dds_set_status_mask(r, DDS_DATA_AVAILABLE_STATUS);
    if (const auto rc = dds_waitset_attach(waitset_.get(), r, r); rc < 0)
      throw std::runtime_error(std::string("DDS: cannot attach reader to waitset: ") + dds_strretcode(rc));
  }
  thread_ = std::thread([this] { run(); });
}

DdsBridge::~DdsBridge() {
  stop_.store(true);
  dds_waitset_set_trigger(waitset_.get(), true);
  if (thread_.joinable()) thread_.join();
}

void DdsBridge::run() {
  if (settings_.realtime_priority > 0) {
    sched_param sp{};
    sp.sched_priority = settings_.realtime_priority;
    realtime_ = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
  }
  double last_status_s = 0.0;
  LoopSnapshot last{};
  bool first = true;
  while (!stop_.load()) {
    dds_attach_t triggered[2];
    dds_waitset_wait(waitset_.get(), triggered, 2, DDS_MSECS(2));
    take_commands();
    take_trajectories();
    drain_outcomes();
    const LoopSnapshot& snap = io_.snapshot.read();
    const double now = steady_s();
    const bool changed = first || snap.state != last.state || snap.fault != last.fault || snap.mode != last.mode ||
                         snap.target != last.target || snap.high_voltage != last.high_voltage;
    if (changed || now - last_status_s >= 0.5) {
      publish_status(snap);
      last_status_s = now;
      last = snap;
      first = false;
    }
  }
  drain_outcomes();
  publish_status(io_.snapshot.read());
}

bool DdsBridge::rate_allows(const std::string& client_id, bool trajectory, double now_s) {
  auto it = limiters_.find(client_id);
  if (it == limiters_.end()) {
    if (limiters_.size() > 1024) limiters_.clear();  // bounded: a client churning ids gets a fresh bucket, no more
    it = limiters_
             .emplace(client_id, std::make_pair(RateLimiter(limits_.max_chunks_per_s, limits_.burst_s),
                                                RateLimiter(limits_.max_commands_per_s, limits_.burst_s)))
             .first;
  }
  return trajectory ? it->second.first.allow(now_s) : it->second.second.allow(now_s);
}

bool DdsBridge::is_resend(const std::string& client_id, std::uint64_t seq, bool is_trajectory) {
  auto& list = recent_[client_id];
  for (const auto& r : list) {
    if (r.seq != seq || r.is_trajectory != is_trajectory) continue;
    if (r.answered) write_reply(client_id, seq, is_trajectory, r.reason, r.detail);
    return true;
  }
  if (recent_.size() > 1024) recent_.clear();  // bounded: a client churning ids loses only resend detection
  auto& fresh = recent_[client_id];
  Recent entry;
  entry.seq = seq;
  entry.is_trajectory = is_trajectory;
  fresh.push_back(std::move(entry));
  if (fresh.size() > 32) fresh.pop_front();
  return false;
}

void DdsBridge::count_reject(RejectReason r, const std::string& detail) {
  counters_.rejects_total.fetch_add(1, std::memory_order_relaxed);
  counters_.rejects_by_reason[static_cast<std::size_t>(r)].fetch_add(1, std::memory_order_relaxed);
  last_reject_reason_ = r;
  last_reject_detail_ = detail;
}

void DdsBridge::reply(const std::string& client_id, std::uint64_t seq, bool is_trajectory, RejectReason reason,
                      const std::string& detail) {
  // Back-pressure (busy) is flow control, not a refusal of the client's data: answered, not counted.
  if (reason != RejectReason::accepted && reason != RejectReason::busy) count_reject(reason, detail);
  for (auto& r : recent_[client_id])
    if (r.seq == seq && r.is_trajectory == is_trajectory) {
      r.answered = true;
      r.reason = reason;
      r.detail = detail;
    }
  if (reason == RejectReason::rate_limited) {
    // A flooding client gets at most a few answers per second; every refusal is still counted.
    double& last = last_throttle_reply_s_[client_id];
    const double now = steady_s();
    if (now - last < 0.2) return;
    last = now;
    if (last_throttle_reply_s_.size() > 1024) last_throttle_reply_s_.clear();
  }
  write_reply(client_id, seq, is_trajectory, reason, detail);
}

void DdsBridge::write_reply(const std::string& client_id, std::uint64_t seq, bool is_trajectory, RejectReason reason,
                            const std::string& detail) {
  pvcgel_v1_CommandReply r{};
  dds::copy_bounded(r.rig_id, settings_.rig_id);
  dds::copy_bounded(r.client_id, client_id);
  r.seq = seq;
  r.is_trajectory = is_trajectory;
  r.accepted = reason == RejectReason::accepted;
  r.reason = to_wire(reason);
  dds::copy_bounded(r.detail, detail);
  dds_write(reply_writer_.get(), &r);
}

void DdsBridge::take_trajectories() {
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  std::vector<SetpointSegment> pieces;
  for (;;) {
    const int n = dds_take(trajectory_reader_.get(), samples, infos, kBatch, kBatch);
    if (n <= 0) break;
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* t = static_cast<const pvcgel_v1_Trajectory*>(samples[i]);
      if (settings_.rig_id != t->rig_id) {
        counters_.other_rig.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      const std::string client(t->client_id);
      if (is_resend(client, t->chunk_seq, true)) continue;
      if (!rate_allows(client, true, steady_s())) {
        reply(client, t->chunk_seq, true, RejectReason::rate_limited,
              "more than " + std::to_string(static_cast<int>(limits_.max_chunks_per_s)) + " trajectory chunks/s");
        continue;
      }
      const TrajectoryMessage m = dds::to_trajectory_message(*t);
      const LoopSnapshot& snap = io_.snapshot.read();
      LoopView view;
      view.now_s = snap.now_s;
      view.period_s = identity_.period_s;
      view.target = snap.target;
      view.queued_until_s = snap.queued_until_s;
      view.queued_segments = snap.queued_segments + static_cast<int>(io_.inputs.size());
      pieces.clear();
      Verdict v = validate_trajectory(m, limits_, view, pieces);
      if (v.ok() && pieces.size() > io_.inputs.capacity() - io_.inputs.size())
        v = {RejectReason::queue_full, "the input queue to the loop is full; send slower"};
      if (!v.ok()) {
        reply(client, t->chunk_seq, true, v.reason, v.detail);
        continue;
      }
      const std::uint32_t ticket = new_ticket();
      pending_[ticket] = Pending{client, t->chunk_seq, true};
      for (std::size_t k = 0; k < pieces.size(); ++k) {
        LoopInput in;
        in.type = LoopInput::Type::segment;
        in.ticket = ticket;
        in.last_piece = k + 1 == pieces.size();
        in.segment = pieces[k];
        io_.inputs.push(in);  // room was checked above; this thread is the only producer
      }
    }
    dds_return_loan(trajectory_reader_.get(), samples, n);
  }
}

void DdsBridge::take_commands() {
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  for (;;) {
    const int n = dds_take(command_reader_.get(), samples, infos, kBatch, kBatch);
    if (n <= 0) break;
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* c = static_cast<const pvcgel_v1_Command*>(samples[i]);
      if (settings_.rig_id != c->rig_id) {
        counters_.other_rig.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      const std::string client(c->client_id);
      if (is_resend(client, c->command_seq, false)) continue;
      if (!rate_allows(client, false, steady_s())) {
        reply(client, c->command_seq, false, RejectReason::rate_limited,
              "more than " + std::to_string(static_cast<int>(limits_.max_commands_per_s)) + " commands/s");
        continue;
      }
      Verdict v = validate_command(c->kind, c->argument, c->client_id, c->command_seq);
      const auto kind = from_wire<CommandKind>(c->kind);  // validate_command refused an unknown kind already
      if (v.ok() && !kind) v = {RejectReason::unknown_command, "command kind " + std::to_string(c->kind) + " is unknown"};
      if (v.ok() && io_.inputs.size() >= io_.inputs.capacity())
        v = {RejectReason::queue_full, "the input queue to the loop is full; send slower"};
      if (!v.ok()) {
        reply(client, c->command_seq, false, v.reason, v.detail);
        continue;
      }
      const std::uint32_t ticket = new_ticket();
      pending_[ticket] = Pending{client, c->command_seq, false};
      LoopInput in;
      in.type = LoopInput::Type::command;
      in.command = *kind;
      in.argument = c->argument;
      in.ticket = ticket;
      io_.inputs.push(in);
    }
    dds_return_loan(command_reader_.get(), samples, n);
  }
}

void DdsBridge::drain_outcomes() {
  while (auto o = io_.outcomes.pop()) {
    const auto it = pending_.find(o->ticket);
    if (it == pending_.end()) continue;
    const Pending p = it->second;
    pending_.erase(it);
    if (o->reason == RejectReason::accepted) {
      (p.is_trajectory ? counters_.chunks_accepted : counters_.commands_accepted).fetch_add(1, std::memory_order_relaxed);
      reply(p.client_id, p.seq, p.is_trajectory, o->reason, "");
    } else {
      reply(p.client_id, p.seq, p.is_trajectory, o->reason, detail_for_loop_refusal(o->reason, o->state, o->cause));
    }
  }
}

void DdsBridge::publish_status(const LoopSnapshot& snap) {
  pvcgel_v1_Status s{};
  dds::copy_bounded(s.rig_id, settings_.rig_id);
  s.t_s = snap.now_s;
  s.state = to_wire(snap.state);
  s.fault = to_wire(snap.fault);
  s.mode = to_wire(snap.mode);
  s.target = to_wire(snap.target);
  s.high_voltage = snap.high_voltage;
  s.period_s = identity_.period_s;
  s.queued_until_s = snap.queued_until_s;
  s.cycles = stats_.cycles.load(std::memory_order_relaxed);
  s.overruns = stats_.overruns.load(std::memory_order_relaxed);
  s.records_dropped = stats_.records_dropped.load(std::memory_order_relaxed);
  s.latency_p50_us = static_cast<float>(stats_.wakeup_latency.quantile_us(0.5));
  s.latency_p99_us = static_cast<float>(stats_.wakeup_latency.quantile_us(0.99));
  s.latency_p999_us = static_cast<float>(stats_.wakeup_latency.quantile_us(0.999));
  s.latency_max_us = static_cast<float>(static_cast<double>(stats_.wakeup_latency.max_ns()) * 1e-3);
  s.compute_p99_us = static_cast<float>(stats_.compute_time.quantile_us(0.99));
  s.chunks_accepted = counters_.chunks_accepted.load(std::memory_order_relaxed);
  s.commands_accepted = counters_.commands_accepted.load(std::memory_order_relaxed);
  s.rejects_total = counters_.rejects_total.load(std::memory_order_relaxed);
  for (std::size_t i = 0; i < counters_.rejects_by_reason.size() && i < std::size(s.rejects_by_reason); ++i)
    s.rejects_by_reason[i] = counters_.rejects_by_reason[i].load(std::memory_order_relaxed);
  s.last_reject_reason = to_wire(last_reject_reason_);
  dds::copy_bounded(s.last_reject_detail, last_reject_detail_);
  dds::copy_bounded(s.config_hash, identity_.config_hash);
  dds::copy_bounded(s.version, identity_.version);
  dds::copy_bounded(s.hal_backend, identity_.hal_backend);
  dds_write(status_writer_.get(), &s);
}

}  // namespace pvcgel::daemon
