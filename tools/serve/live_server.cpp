#include "tools/serve/live_server.hpp"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <thread>

#include "tools/serve/control_worker.hpp"
#include "tools/serve/ws_transport.hpp"

namespace pvcgel::tools::serve {

namespace {

using nlohmann::json;
using Conn = WsTransport::ConnectionId;
using Clock = std::chrono::steady_clock;

/// Largest message a client may send; Foxglove's requests are a few hundred bytes.
constexpr std::size_t kMaxClientMessage = 64 * 1024;
/// Bytes websocketpp may hold unsent for one client before we stop handing it more.
constexpr std::size_t kMaxBuffered = 2 * 1024 * 1024;
/// Rigs served at most: anyone on the domain can publish rig ids, each costs channels and memory.
constexpr std::size_t kMaxRigs = 64;
/// Client-published channels one client may hold (two per rig make sense).
constexpr std::size_t kMaxClientChannels = 16;
/// The refusal of every control request (service call or client publish) without --allow-control.
constexpr const char* kControlDisabled =
    "control is disabled: this pvcgel serve only watches (start it with --allow-control to arm, start, stop, reset, "
    "change mode or send references)";

/// Channel offsets within a rig's block of ids (rig k: 1 + 8 k + offset).
enum Topic : std::uint32_t { telemetry, telemetry_decimated, telemetry_batch, status, command_reply, kTopics };
/// Channel ids: rig i's topic k is 1 + 8 i + k (0 is not a valid channel id; 8 leaves room for new topics).
constexpr std::uint32_t kChannelsPerRig = 8;
constexpr std::uint32_t channel_id(std::uint32_t rig_index, std::uint32_t topic) noexcept {
  return 1 + kChannelsPerRig * rig_index + topic;
}
constexpr const char* kTopicNames[] = {"telemetry", "telemetry_decimated", "telemetry_batch", "status", "command_reply"};

std::shared_ptr<const std::string> shared(std::string s) { return std::make_shared<const std::string>(std::move(s)); }

std::string read_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in)
    throw std::runtime_error("cannot read the page file " + p.string() +
                             " (run .ci/install-deps, which runs npm ci in tools/serve/web, or pass --web-root DIR)");
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class LiveServer final : public RigSink {
 public:
  explicit LiveServer(const ServeOptions& o);
  int run();

  void on_telemetry(const pvcgel_v1_Telemetry& t) override;
  void on_status(const pvcgel_v1_Status& s) override;
  void on_reply(const pvcgel_v1_CommandReply& r) override;
  void on_presence(const std::string& rig, bool present) override;
  void on_tick() override;

 private:
  /// A channel a client advertised to publish control requests on (clientPublish).
  struct ClientChannel {
    std::string topic;
    std::string rig;
    ControlWorker::Kind kind;
  };
  struct Client {
    std::uint64_t id = 0;
    Conn conn = 0;
    std::string peer;
    ClientQueue queue;
    std::map<std::uint32_t, std::uint32_t> subscriptions;  // subscription id -> channel id
    std::map<std::uint32_t, ClientChannel> published;      // client channel id -> what it publishes on
    bool drain_posted = false;
    std::uint64_t reported_drops = 0;
  };
  struct Rig {
    std::string id;
    std::uint32_t index = 0;
    TelemetryBatcher batcher;
    Clock::time_point next_batch = Clock::now();
    std::uint64_t decimation_count = 0;
  };

  /// The rig's record, made (and advertised) on first sight; nullptr beyond kMaxRigs.
  Rig* rig_locked(const std::string& id);
  bool subscribed_locked(std::uint32_t channel) const;
  json channels_of(const Rig& rig) const;
  json services_of(const Rig& rig) const;
  void publish_locked(std::uint32_t channel, std::uint64_t log_time_ns, const std::string& payload, bool protocol);
  /// A Status or CommandReply on its rig's channel, stamped with the wall clock.
  void publish_now(const std::string& rig_id, std::uint32_t topic, const json& message);
  void broadcast_locked(const std::string& text);
  void send_protocol_locked(Client& c, std::string data, bool binary);
  void schedule_drain_locked(Client& c);
  void drain(std::uint64_t client_id);
  void drain_all();

  void on_open(Conn h);
  void on_close(Conn h);
  void on_message(Conn h, const std::string& data, bool binary);
  void handle_text(Client& c, const std::string& text);
  void handle_service_call(Client& c, const std::string& frame);
  void handle_client_advertise(Client& c, const json& m);
  void handle_client_message(Client& c, const std::string& frame);
  /// Runs `request` on the control worker; `answer` gets the client back (if still connected) with the result.
  using Answer = std::function<void(Client& c, bool ok, const std::string& result)>;
  bool submit_control_locked(const Client& c, const std::string& rig, ControlWorker::Kind kind, json request,
                             Answer answer);
  void status_locked(Client& c, int level, const std::string& message);
  void disconnect(Conn h, CloseCode code, const std::string& reason);
  /// Disconnects from the network thread, after the lock (mutex_) is released.
  void disconnect_later(const Client& c, CloseCode code, std::string reason);
  Client* client_locked(Conn h);
  WsTransport::Files load_page() const;

  ServeOptions opt_;
  std::unique_ptr<WsTransport> ws_;
  std::unique_ptr<ControlWorker> worker_;
  std::string session_id_;

  std::mutex mutex_;  // clients_ and rigs_: the watcher thread and the network thread
  std::map<std::uint64_t, std::unique_ptr<Client>> clients_;
  std::map<std::string, std::unique_ptr<Rig>> rigs_;
  std::vector<Rig*> rig_by_index_;
  bool rig_limit_logged_ = false;
  std::atomic<bool> stop_{false};
  Clock::time_point last_drop_report_ = Clock::now();
};

LiveServer::LiveServer(const ServeOptions& o) : opt_(o) {
  session_id_ = std::to_string(std::chrono::system_clock::now().time_since_epoch().count());
  WsTransport::Handlers handlers{[this](Conn c) { on_open(c); }, [this](Conn c) { on_close(c); },
                                 [this](Conn c, const std::string& data, bool binary) { on_message(c, data, binary); }};
  ws_ = std::make_unique<WsTransport>(opt_.bind, opt_.port, load_page(), kSubprotocol, kMaxClientMessage, std::move(handlers));
  if (opt_.allow_control) worker_ = std::make_unique<ControlWorker>(opt_.dds);
}

WsTransport::Files LiveServer::load_page() const {
  WsTransport::Files files;
  const std::filesystem::path root = opt_.web_root;
  const std::filesystem::path uplot = root / "node_modules" / "uplot" / "dist";
  const std::pair<const char*, std::filesystem::path> kFiles[] = {
      {"/", root / "index.html"},          {"/index.html", root / "index.html"},
      {"/app.js", root / "app.js"},        {"/style.css", root / "style.css"},
      {"/uplot/uPlot.esm.js", uplot / "uPlot.esm.js"}, {"/uplot/uPlot.min.css", uplot / "uPlot.min.css"}};
  for (const auto& [url, path] : kFiles) {
    const std::string ext = path.extension().string();
    const std::string type = ext == ".html" ? "text/html; charset=utf-8"
                             : ext == ".css" ? "text/css; charset=utf-8"
                                             : "text/javascript; charset=utf-8";
    files[url] = {read_file(path), type};
  }
  return files;
}

json LiveServer::channels_of(const Rig& rig) const {
  const std::string schemas[] = {telemetry_schema(), telemetry_schema(), batch_schema(), status_schema(), reply_schema()};
  const char* names[] = {"pvcgel.v1.Telemetry", "pvcgel.v1.Telemetry", "pvcgel.serve.TelemetryBatch", "pvcgel.v1.Status",
                         "pvcgel.v1.CommandReply"};
  json channels = json::array();
  for (std::uint32_t k = 0; k < kTopics; ++k)
    channels.push_back({{"id", channel_id(rig.index, k)},
                        {"topic", "/" + rig.id + "/" + kTopicNames[k]},
                        {"encoding", "json"},
                        {"schemaName", names[k]},
                        {"schema", schemas[k]},
                        {"schemaEncoding", "jsonschema"}});
  return channels;
}

json LiveServer::services_of(const Rig& rig) const {
  const auto def = [](const char* name, const std::string& schema) {
    return json{{"encoding", "json"}, {"schemaName", name}, {"schemaEncoding", "jsonschema"}, {"schema", schema}};
  };
  json services = json::array();
  const std::pair<const char*, std::string> kinds[] = {{"command", command_request_schema()},
                                                       {"reference", reference_request_schema()}};
  for (std::uint32_t k = 0; k < 2; ++k) {
    const std::string type = k == 0 ? "pvcgel.serve.CommandRequest" : "pvcgel.serve.ReferenceRequest";
    services.push_back({{"id", 1 + 2 * rig.index + k},
                        {"name", "/" + rig.id + "/" + kinds[k].first},
                        {"type", type},
                        {"request", def(type.c_str(), kinds[k].second)},
                        {"response", def("pvcgel.serve.ControlResponse", control_response_schema())},
                        {"requestSchema", kinds[k].second},
                        {"responseSchema", control_response_schema()}});
  }
  return services;
}

LiveServer::Rig* LiveServer::rig_locked(const std::string& id) {
  if (const auto it = rigs_.find(id); it != rigs_.end()) return it->second.get();
  if (rigs_.size() >= kMaxRigs) {
    if (!rig_limit_logged_)
      std::fprintf(stderr, "pvcgel serve: more than %zu rig ids on domain %d: ignoring '%s' and any further ones\n",
                   kMaxRigs, opt_.dds.domain, id.c_str());
    rig_limit_logged_ = true;
    return nullptr;
  }
  auto& rig = rigs_[id];
  rig = std::make_unique<Rig>(Rig{id, static_cast<std::uint32_t>(rig_by_index_.size()),
                                  TelemetryBatcher(opt_.page_decimation), Clock::now(), 0});
  rig_by_index_.push_back(rig.get());
  std::fprintf(stderr, "pvcgel serve: rig '%s' on domain %d: advertising its channels\n", id.c_str(), opt_.dds.domain);
  broadcast_locked(json{{"op", "advertise"}, {"channels", channels_of(*rig)}}.dump());
  broadcast_locked(json{{"op", "advertiseServices"}, {"services", services_of(*rig)}}.dump());
  return rig.get();
}

void LiveServer::schedule_drain_locked(Client& c) {
  if (c.drain_posted) return;
  c.drain_posted = true;
  ws_->post([this, id = c.id] { drain(id); });
}

void LiveServer::send_protocol_locked(Client& c, std::string data, bool binary) {
  if (!c.queue.push_protocol(Frame{shared(std::move(data)), binary})) {
    disconnect_later(c, kTryAgainLater, "client too slow: protocol backlog over 1024 messages");
  }
  schedule_drain_locked(c);
}

void LiveServer::broadcast_locked(const std::string& text) {
  for (auto& [id, c] : clients_) send_protocol_locked(*c, text, false);
}

void LiveServer::publish_locked(std::uint32_t channel, std::uint64_t log_time_ns, const std::string& payload,
                                bool protocol) {
  for (auto& [id, c] : clients_) {
    for (const auto& [sub, ch] : c->subscriptions) {
      if (ch != channel) continue;
      std::string frame = message_data_frame(sub, log_time_ns, payload);
      if (protocol) {
        send_protocol_locked(*c, std::move(frame), true);
      } else {
        c->queue.push_data(Frame{shared(std::move(frame)), true});
        schedule_drain_locked(*c);
      }
    }
  }
}

bool LiveServer::subscribed_locked(std::uint32_t channel) const {
  for (const auto& [id, c] : clients_)
    for (const auto& [sub, ch] : c->subscriptions)
      if (ch == channel) return true;
  return false;
}

void LiveServer::on_telemetry(const pvcgel_v1_Telemetry& t) {
  std::lock_guard lock(mutex_);
  Rig* found = rig_locked(t.rig_id);
  if (!found) return;
  Rig& rig = *found;
  rig.batcher.add(t);
  const bool decimated = rig.decimation_count++ % static_cast<std::uint64_t>(opt_.foxglove_decimation) == 0;
  const bool every = subscribed_locked(channel_id(rig.index, telemetry));
  if (!every && !(decimated && subscribed_locked(channel_id(rig.index, telemetry_decimated)))) return;  // nobody wants this sample alone
  const std::string payload = to_json(t).dump();
  const auto stamp = static_cast<std::uint64_t>(t.stamp_ns);
  if (every) publish_locked(channel_id(rig.index, telemetry), stamp, payload, false);
  if (decimated) publish_locked(channel_id(rig.index, telemetry_decimated), stamp, payload, false);
}

void LiveServer::on_status(const pvcgel_v1_Status& s) { publish_now(s.rig_id, status, to_json(s)); }

void LiveServer::on_reply(const pvcgel_v1_CommandReply& r) { publish_now(r.rig_id, command_reply, to_json(r)); }

void LiveServer::publish_now(const std::string& rig_id, std::uint32_t topic, const json& message) {
  std::lock_guard lock(mutex_);
  const Rig* rig = rig_locked(rig_id);
  if (!rig) return;
  const auto now_ns = static_cast<std::uint64_t>(std::chrono::system_clock::now().time_since_epoch().count());
  publish_locked(channel_id(rig->index, topic), now_ns, message.dump(), true);
}

void LiveServer::on_presence(const std::string& rig, bool present) {
  std::lock_guard lock(mutex_);
  const std::string message = present ? "rig '" + rig + "': daemon present"
                                      : "rig '" + rig + "': no daemon (no Status for 2 s)";
  std::fprintf(stderr, "pvcgel serve: %s\n", message.c_str());
  broadcast_locked(json{{"op", "status"}, {"level", present ? 0 : 1}, {"message", message}, {"id", "presence:" + rig}}.dump());
}

void LiveServer::on_tick() {
  std::lock_guard lock(mutex_);
  const auto now = Clock::now();
  for (auto& [id, rig] : rigs_) {
    if (rig->batcher.empty() || now < rig->next_batch) continue;
    // On a fixed grid, so the page gets exactly 1 / period batches (= frames) a
    // second whatever the DDS thread's wake-up granularity; no burst after a stall.
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(opt_.page_batch_period_s));
    rig->next_batch = std::max(rig->next_batch + period, now - period);
    std::uint64_t log_time_ns = 0;
    json batch = rig->batcher.take(log_time_ns);
    batch["rig_id"] = rig->id;
    publish_locked(channel_id(rig->index, telemetry_batch), log_time_ns, batch.dump(), false);
  }
}

LiveServer::Client* LiveServer::client_locked(Conn h) {
  const auto c = clients_.find(h);
  return c == clients_.end() ? nullptr : c->second.get();
}

void LiveServer::on_open(Conn h) {
  std::lock_guard lock(mutex_);
  auto c = std::make_unique<Client>();
  c->id = h;
  c->conn = h;
  c->peer = ws_->peer(h);
  std::fprintf(stderr, "pvcgel serve: client %llu (%s) connected\n", static_cast<unsigned long long>(c->id), c->peer.c_str());
  const json info{{"op", "serverInfo"},
                  {"name", "pvcgel serve (DDS domain " + std::to_string(opt_.dds.domain) + ")"},
                  {"capabilities", json::array({"services", "clientPublish"})},
                  {"supportedEncodings", json::array({"json"})},
                  {"metadata",
                   {{"domain", std::to_string(opt_.dds.domain)},
                    {"allow_control", opt_.allow_control ? "true" : "false"},
                    {"default_rig", opt_.dds.rig},
                    {"page_decimation", std::to_string(opt_.page_decimation)}}},
                  {"sessionId", session_id_}};
  send_protocol_locked(*c, info.dump(), false);
  json channels = json::array(), services = json::array();
  for (const Rig* rig : rig_by_index_) {
    for (auto& ch : channels_of(*rig)) channels.push_back(ch);
    for (auto& sv : services_of(*rig)) services.push_back(sv);
  }
  if (!channels.empty()) {
    send_protocol_locked(*c, json{{"op", "advertise"}, {"channels", channels}}.dump(), false);
    send_protocol_locked(*c, json{{"op", "advertiseServices"}, {"services", services}}.dump(), false);
  }
  clients_[h] = std::move(c);
}

void LiveServer::on_close(Conn h) {
  std::lock_guard lock(mutex_);
  const auto c = clients_.find(h);
  if (c == clients_.end()) return;
  std::fprintf(stderr, "pvcgel serve: client %llu (%s) disconnected; %llu data messages dropped for it (too slow)\n",
               static_cast<unsigned long long>(c->first), c->second->peer.c_str(),
               static_cast<unsigned long long>(c->second->queue.dropped()));
  clients_.erase(c);
}

void LiveServer::drain(std::uint64_t client_id) {
  std::vector<Frame> out;
  {
    std::lock_guard lock(mutex_);
    const auto it = clients_.find(client_id);
    if (it == clients_.end()) return;
    Client& c = *it->second;
    c.drain_posted = false;
    if (!ws_->is_open(c.conn)) return;
    // Hand the socket only what it is taking; the rest waits in the bounded queue.
    std::size_t buffered = ws_->buffered(c.conn);
    while (buffered < kMaxBuffered && out.size() < 512) {
      auto f = c.queue.pop();
      if (!f) break;
      buffered += f->data->size();
      out.push_back(std::move(*f));
    }
  }
  for (const auto& f : out) ws_->send(client_id, *f.data, f.binary);
}

void LiveServer::drain_all() {
  std::vector<std::uint64_t> ids;
  {
    std::lock_guard lock(mutex_);
    const bool report = Clock::now() - last_drop_report_ > std::chrono::seconds(1);
    if (report) last_drop_report_ = Clock::now();
    for (auto& [id, c] : clients_) {
      if (report && c->queue.dropped() > c->reported_drops) {
        const std::string message = std::to_string(c->queue.dropped() - c->reported_drops) +
                                    " messages dropped for this client in the last second (it reads too slowly)";
        c->reported_drops = c->queue.dropped();
        c->queue.push_protocol(Frame{shared(json{{"op", "status"}, {"level", 1}, {"message", message}}.dump()), false});
      }
      if (c->queue.size() > 0) ids.push_back(id);
    }
  }
  for (const auto id : ids) drain(id);
}

void LiveServer::disconnect(Conn h, CloseCode code, const std::string& reason) {
  std::fprintf(stderr, "pvcgel serve: disconnecting client %llu (%s): %s\n", static_cast<unsigned long long>(h),
               ws_->peer(h).c_str(), reason.c_str());
  ws_->close(h, code, reason);
}

void LiveServer::disconnect_later(const Client& c, CloseCode code, std::string reason) {
  ws_->post([this, conn = c.conn, code, reason = std::move(reason)] { disconnect(conn, code, reason); });
}

void LiveServer::on_message(Conn h, const std::string& data, bool binary) {
  std::unique_lock lock(mutex_);
  Client* c = client_locked(h);
  if (!c) return;
  if (!binary) {
    try {
      handle_text(*c, data);
    } catch (const std::exception& e) {
      lock.unlock();
      disconnect(h, kPolicyViolation, e.what());
    }
    return;
  }
  if (!data.empty() && data[0] == 0x01) return handle_client_message(*c, data);
  if (!data.empty() && data[0] == 0x02) return handle_service_call(*c, data);
  const int op = data.empty() ? -1 : static_cast<unsigned char>(data[0]);
  lock.unlock();
  disconnect(h, kUnsupportedData, "unknown binary opcode " + std::to_string(op));
}

void LiveServer::status_locked(Client& c, int level, const std::string& message) {
  send_protocol_locked(c, json{{"op", "status"}, {"level", level}, {"message", message}}.dump(), false);
}

void LiveServer::handle_text(Client& c, const std::string& text) {
  const json m = json::parse(text, nullptr, false);
  if (m.is_discarded()) throw std::runtime_error("invalid JSON message (" + std::to_string(text.size()) + " bytes)");
  if (!m.is_object() || !m.contains("op") || !m["op"].is_string()) throw std::runtime_error("message without a string \"op\"");
  const std::string op = m["op"];
  const auto status = [&](int level, const std::string& message) { status_locked(c, level, message); };
  if (op == "subscribe") {
    if (!m.contains("subscriptions") || !m["subscriptions"].is_array()) throw std::runtime_error("subscribe without a \"subscriptions\" array");
    for (const auto& s : m["subscriptions"]) {
      if (!s.is_object() || !s.contains("id") || !s["id"].is_number_unsigned() || !s.contains("channelId") ||
          !s["channelId"].is_number_unsigned())
        throw std::runtime_error("subscribe: each subscription needs unsigned \"id\" and \"channelId\"");
      const auto channel = s["channelId"].get<std::uint32_t>();
      const auto rig = (channel - 1) / kChannelsPerRig;
      if (channel == 0 || rig >= rig_by_index_.size() || (channel - 1) % kChannelsPerRig >= kTopics) {
        status(2, "subscribe: unknown channel " + std::to_string(channel));
        continue;
      }
      c.subscriptions[s["id"].get<std::uint32_t>()] = channel;
    }
  } else if (op == "unsubscribe") {
    if (!m.contains("subscriptionIds") || !m["subscriptionIds"].is_array()) throw std::runtime_error("unsubscribe without a \"subscriptionIds\" array");
    for (const auto& id : m["subscriptionIds"])
      if (id.is_number_unsigned()) c.subscriptions.erase(id.get<std::uint32_t>());
  } else if (op == "advertise") {
    handle_client_advertise(c, m);
  } else if (op == "unadvertise") {
    if (!m.contains("channelIds") || !m["channelIds"].is_array()) throw std::runtime_error("unadvertise without a \"channelIds\" array");
    for (const auto& id : m["channelIds"])
      if (id.is_number_unsigned()) c.published.erase(id.get<std::uint32_t>());
  } else if (op == "getParameters" || op == "setParameters" ||
             op == "subscribeParameterUpdates" || op == "unsubscribeParameterUpdates" ||
             op == "subscribeConnectionGraph" || op == "unsubscribeConnectionGraph" || op == "fetchAsset") {
    status(1, "'" + op + "' is not supported by this server (capabilities: services, clientPublish)");
  } else {
    throw std::runtime_error("unknown op '" + op.substr(0, 40) + "'");
  }
}

void LiveServer::handle_service_call(Client& c, const std::string& frame) {
  std::string error;
  const auto call = parse_service_call(frame, error);
  if (!call) return disconnect_later(c, kPolicyViolation, error);
  const auto fail = [&](const std::string& message) {
    send_protocol_locked(c,
                         json{{"op", "serviceCallFailure"}, {"serviceId", call->service_id}, {"callId", call->call_id},
                              {"message", message}}
                             .dump(),
                         false);
  };
  const std::uint32_t rig_index = (call->service_id - 1) / 2;
  if (call->service_id == 0 || rig_index >= rig_by_index_.size()) return fail("unknown service " + std::to_string(call->service_id));
  if (!opt_.allow_control) return fail(kControlDisabled);
  if (call->encoding != "json") return fail("unsupported encoding '" + call->encoding + "' (json only)");
  json request = json::parse(call->payload, nullptr, false);
  if (request.is_discarded()) return fail("the request is not valid JSON");
  const auto kind = (call->service_id - 1) % 2 == 0 ? ControlWorker::Kind::command : ControlWorker::Kind::reference;
  const auto sid = call->service_id, cid = call->call_id;
  const bool queued = submit_control_locked(c, rig_by_index_[rig_index]->id, kind, std::move(request),
                                            [this, sid, cid](Client& to, bool ok, const std::string& result) {
    if (ok) send_protocol_locked(to, service_response_frame(sid, cid, "json", result), true);
    else
      send_protocol_locked(to, json{{"op", "serviceCallFailure"}, {"serviceId", sid}, {"callId", cid}, {"message", result}}.dump(),
                           false);
  });
  if (!queued) fail("busy: 8 control requests are already waiting for the daemon");
}

bool LiveServer::submit_control_locked(const Client& c, const std::string& rig, ControlWorker::Kind kind, json request,
                                       Answer answer) {
  return worker_->submit(rig, kind, std::move(request),
                         [this, client_id = c.id, answer = std::move(answer)](bool ok, const std::string& result) {
    std::lock_guard lock(mutex_);
    const auto it = clients_.find(client_id);
    if (it != clients_.end()) answer(*it->second, ok, result);
  });
}

void LiveServer::handle_client_advertise(Client& c, const json& m) {
  if (!m.contains("channels") || !m["channels"].is_array()) throw std::runtime_error("advertise without a \"channels\" array");
  for (const auto& ch : m["channels"]) {
    if (!ch.is_object() || !ch.contains("id") || !ch["id"].is_number_unsigned() || !ch.contains("topic") ||
        !ch["topic"].is_string() || !ch.contains("encoding") || !ch["encoding"].is_string())
      throw std::runtime_error("advertise: each channel needs unsigned \"id\", string \"topic\" and \"encoding\"");
    const std::string topic = ch["topic"], encoding = ch["encoding"];
    const auto refuse = [&](const std::string& why) { status_locked(c, 2, "client channel '" + topic.substr(0, 80) + "' refused: " + why); };
    std::string error;
    const auto parsed = parse_client_topic(topic, error);
    if (!opt_.allow_control) refuse(kControlDisabled);
    else if (!parsed) refuse(error);
    else if (!rigs_.contains(parsed->rig)) refuse("no rig '" + parsed->rig + "' on DDS domain " + std::to_string(opt_.dds.domain));
    else if (encoding != "json") refuse("encoding '" + encoding.substr(0, 40) + "' (json only)");
    else if (c.published.size() >= kMaxClientChannels) refuse("at most " + std::to_string(kMaxClientChannels) + " client channels");
    else {
      const auto kind = parsed->kind == "command" ? ControlWorker::Kind::command : ControlWorker::Kind::reference;
      c.published[ch["id"].get<std::uint32_t>()] = ClientChannel{topic, parsed->rig, kind};
      status_locked(c, 0, "client channel '" + topic + "' accepted: each message goes to the daemon; its reply comes back "
                          "as a status message and on /" + parsed->rig + "/command_reply");
    }
  }
}

void LiveServer::handle_client_message(Client& c, const std::string& frame) {
  std::string error;
  const auto msg = parse_client_message(frame, error);
  if (!msg) return disconnect_later(c, kPolicyViolation, error);
  const std::string not_sent = "message on client channel " + std::to_string(msg->channel_id) + " not sent: ";
  if (!opt_.allow_control) return status_locked(c, 2, not_sent + kControlDisabled);
  const auto ch = c.published.find(msg->channel_id);
  if (ch == c.published.end()) return status_locked(c, 2, not_sent + "the channel was not advertised (or was refused)");
  json request = json::parse(msg->payload, nullptr, false);
  if (request.is_discarded()) return status_locked(c, 2, not_sent + "not valid JSON");
  const std::string what = ch->second.topic + " " + request.dump().substr(0, 200);
  const bool queued = submit_control_locked(c, ch->second.rig, ch->second.kind, std::move(request),
                                            [this, what](Client& to, bool ok, const std::string& result) {
    if (!ok) return status_locked(to, 2, what + ": failed: " + result);
    const json r = json::parse(result);
    const bool accepted = r["accepted"].get<bool>();
    status_locked(to, accepted ? 0 : 1,
                  what + (accepted ? ": accepted by the daemon"
                                   : ": refused by the daemon: " + r["reason"].get<std::string>() + ": " +
                                         r["detail"].get<std::string>()));
  });
  if (!queued) status_locked(c, 2, not_sent + "busy: 8 control requests are already waiting for the daemon");
}

int LiveServer::run() {
  RigWatcher watcher(opt_.dds, opt_.reliable_telemetry);
  std::printf("pvcgel serve: page http://%s:%d/ , Foxglove ws://%s:%d (DDS domain %d, control %s)\n", opt_.bind.c_str(),
              ws_->port(), opt_.bind.c_str(), ws_->port(), opt_.dds.domain, opt_.allow_control ? "allowed" : "off");
  std::fflush(stdout);
  ws_->on_signal([this] {
    stop_ = true;
    ws_->shutdown();
  });
  ws_->every(std::chrono::milliseconds(20), [this] { drain_all(); });
  std::thread dds_thread([&] { watcher.run(*this, stop_); });
  ws_->run();
  stop_ = true;
  dds_thread.join();
  std::fprintf(stderr, "pvcgel serve: stopped\n");
  return 0;
}

}  // namespace

int run_live_server(const ServeOptions& o) {
  LiveServer server(o);
  return server.run();
}

}  // namespace pvcgel::tools::serve
