#include "tools/serve/live_messages.hpp"

#include <cmath>
#include <cstring>
#include <span>
#include <vector>

#include "control/controller.hpp"
#include "daemon/control_loop.hpp"
#include "daemon/input_validation.hpp"
#include "pvcgel_v1_json_fields.hpp"

namespace pvcgel::tools::serve {

namespace {

using nlohmann::json;

/// One field in a JSON schema. The IDL's fields come from tables generated at
/// build time from daemon/dds/pvcgel_v1.idl (tools/serve/idl_json_schema.py);
/// the fields below are the names `pvcgel serve` adds.
using Field = idl::Field;

constexpr Field kTelemetryNames[] = {
    {"mode_name", "string", "mode by name"},
    {"state_name", "string", "state by name"},
    {"fault_name", "string", "fault reason by name"},
};

constexpr Field kStatusNames[] = {
    {"state_name", "string", "state by name"},
    {"mode_name", "string", "mode by name"},
    {"fault_name", "string", "fault reason by name"},
    {"last_reject_reason_name", "string", "last refusal's reason by name"},
};

constexpr Field kReplyNames[] = {
    {"reason_name", "string", "reason by name"},
};

std::string schema(const char* title, std::span<const Field> fields, std::span<const Field> added = {}) {
  json props = json::object();
  json required = json::array();
  std::vector<Field> all(fields.begin(), fields.end());
  all.insert(all.end(), added.begin(), added.end());
  for (const auto& f : all) {
    json p{{"description", f.description}};
    if (std::strcmp(f.type, "number|null") == 0) p["type"] = json::array({"number", "null"});
    else p["type"] = f.type;
    if (std::strcmp(f.type, "array") == 0) p["items"] = {{"type", "integer"}};
    props[f.name] = p;
    required.push_back(f.name);
  }
  return json{{"$schema", "https://json-schema.org/draft/2020-12/schema"},
              {"title", title},
              {"type", "object"},
              {"properties", props},
              {"required", required}}
      .dump();
}

json number(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

std::string unknown(std::uint8_t v) { return "unknown(" + std::to_string(v) + ")"; }

void put_u32(std::string& s, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
void put_u64(std::string& s, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
std::uint32_t get_u32(std::string_view s, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(s[at + static_cast<std::size_t>(i)]);
  return v;
}

}  // namespace

// The live view shows what arrived, even from a daemon of another version: an unknown value is named
// "unknown(N)" on the page (never cast or used as an index), rather than ending the stream.
template <typename E>
std::string name_or_unknown(std::uint8_t v) {
  const auto e = from_wire<E>(v);
  return e ? std::string(to_string(*e)) : unknown(v);
}

std::string state_name(std::uint8_t v) { return name_or_unknown<daemon::LoopState>(v); }
std::string fault_name(std::uint8_t v) { return name_or_unknown<daemon::FaultReason>(v); }
std::string mode_name(std::uint8_t v) { return name_or_unknown<control::ControllerMode>(v); }
std::string reason_name(std::uint8_t v) { return name_or_unknown<daemon::RejectReason>(v); }

json to_json(const pvcgel_v1_Telemetry& t) {
  return json{{"rig_id", t.rig_id},         {"seq", t.seq},
              {"t_s", t.t_s},               {"r_um", number(t.r_um)},
              {"y_um", number(t.y_um)},     {"u_V", number(t.u_V)},
              {"e_um", number(t.e_um)},     {"d_hat", number(t.d_hat)},
              {"latency_us", t.latency_us}, {"mode", t.mode},
              {"state", t.state},           {"fault", t.fault},
              {"high_voltage", t.high_voltage}, {"target", t.target},
              {"chunk_seq", t.chunk_seq},   {"stamp_ns", t.stamp_ns},
              {"mode_name", mode_name(t.mode)}, {"state_name", state_name(t.state)},
              {"fault_name", fault_name(t.fault)}};
}

json to_json(const pvcgel_v1_Status& s) {
  json by_reason = json::array();
  for (const auto n : s.rejects_by_reason) by_reason.push_back(n);
  return json{{"rig_id", s.rig_id},
              {"t_s", s.t_s},
              {"state", s.state},
              {"fault", s.fault},
              {"mode", s.mode},
              {"target", s.target},
              {"high_voltage", s.high_voltage},
              {"period_s", s.period_s},
              {"queued_until_s", s.queued_until_s},
              {"cycles", s.cycles},
              {"overruns", s.overruns},
              {"records_dropped", s.records_dropped},
              {"latency_p50_us", s.latency_p50_us},
              {"latency_p99_us", s.latency_p99_us},
              {"latency_p999_us", s.latency_p999_us},
              {"latency_max_us", s.latency_max_us},
              {"compute_p99_us", s.compute_p99_us},
              {"chunks_accepted", s.chunks_accepted},
              {"commands_accepted", s.commands_accepted},
              {"rejects_total", s.rejects_total},
              {"rejects_by_reason", by_reason},
              {"last_reject_reason", s.last_reject_reason},
              {"last_reject_detail", s.last_reject_detail},
              {"config_hash", s.config_hash},
              {"version", s.version},
              {"hal_backend", s.hal_backend},
              {"state_name", state_name(s.state)},
              {"mode_name", mode_name(s.mode)},
              {"fault_name", fault_name(s.fault)},
              {"last_reject_reason_name", reason_name(s.last_reject_reason)}};
}

json to_json(const pvcgel_v1_CommandReply& r) {
  return json{{"rig_id", r.rig_id},       {"client_id", r.client_id}, {"seq", r.seq},
              {"is_trajectory", r.is_trajectory}, {"accepted", r.accepted}, {"reason", r.reason},
              {"detail", r.detail},       {"reason_name", reason_name(r.reason)}};
}

std::string telemetry_schema() { return schema("pvcgel.v1.Telemetry", idl::kTelemetry, kTelemetryNames); }
std::string status_schema() { return schema("pvcgel.v1.Status", idl::kStatus, kStatusNames); }
std::string reply_schema() { return schema("pvcgel.v1.CommandReply", idl::kCommandReply, kReplyNames); }

std::string batch_schema() {
  static constexpr Field kFields[] = {
      {"rig_id", "string", "rig id"},
      {"t_s", "array", "loop time of the plotted (decimated) samples (s)"},
      {"r_um", "array", "reference of the plotted samples"},
      {"y_um", "array", "displacement of the plotted samples"},
      {"e_um", "array", "error of the plotted samples"},
      {"u_V", "array", "voltage of the plotted samples"},
      {"d_hat", "array", "disturbance estimate of the plotted samples"},
      {"samples", "integer", "samples this batch covers (all of them, not only the plotted ones)"},
      {"first_seq", "integer", "first Telemetry.seq in the batch"},
      {"last_seq", "integer", "last Telemetry.seq in the batch"},
      {"gaps", "integer", "samples missing between first_seq and last_seq"},
      {"stats_n", "integer", "samples with a finite error"},
      {"sum_abs_e_um", "number", "sum of |e| over those samples"},
      {"sum_sq_e_um2", "number", "sum of e^2 over those samples"},
      {"max_abs_e_um", "number", "max |e| over those samples"},
  };
  return schema("pvcgel.serve.TelemetryBatch", kFields);
}

std::string command_request_schema() {
  return json{{"$schema", "https://json-schema.org/draft/2020-12/schema"},
              {"title", "pvcgel.serve.CommandRequest"},
              {"type", "object"},
              {"properties",
               {{"command", {{"type", "string"}, {"enum", {"arm", "start", "stop", "reset", "clear", "mode", "target"}}}},
                {"argument",
                 {{"type", "string"},
                  {"description", "mode: pid | inverse_pid | inverse_pid_dob | inverse_pid_dob_ff; target: "
                                  "displacement | voltage"}}}}},
              {"required", {"command"}}}
      .dump();
}

std::string reference_request_schema() {
  return json{{"$schema", "https://json-schema.org/draft/2020-12/schema"},
              {"title", "pvcgel.serve.ReferenceRequest"},
              {"type", "object"},
              {"properties",
               {{"reference",
                 {{"type", "string"}, {"description", "the paper's references: 0.1Hz, 0.5Hz, 1Hz, multi (or paper-...)"}}},
                {"blend_s", {{"type", "number"}, {"description", "raised-cosine blend from the setpoint in force (s)"}}}}},
              {"required", {"reference"}}}
      .dump();
}

std::string control_response_schema() {
  return json{{"$schema", "https://json-schema.org/draft/2020-12/schema"},
              {"title", "pvcgel.serve.ControlResponse"},
              {"type", "object"},
              {"properties",
               {{"accepted", {{"type", "boolean"}}},
                {"reason", {{"type", "string"}, {"description", "the daemon's RejectReason by name"}}},
                {"detail", {{"type", "string"}}}}},
              {"required", {"accepted", "reason", "detail"}}}
      .dump();
}

void TelemetryBatcher::add(const pvcgel_v1_Telemetry& t) {
  if (have_seq_ && t.seq > last_seq_ + 1) gaps_ += t.seq - last_seq_ - 1;
  if (!have_seq_ || samples_ == 0) first_seq_ = t.seq;
  have_seq_ = true;
  last_seq_ = t.seq;
  last_stamp_ = static_cast<std::uint64_t>(t.stamp_ns);
  ++samples_;
  if (std::isfinite(t.e_um)) {
    ++stats_n_;
    sum_abs_e_ += std::abs(t.e_um);
    sum_sq_e_ += t.e_um * t.e_um;
    max_abs_e_ = std::max(max_abs_e_, std::abs(t.e_um));
  }
  if (t.seq % static_cast<std::uint64_t>(decimation_) != 0) return;
  plot_["t_s"].push_back(t.t_s);
  plot_["r_um"].push_back(number(t.r_um));
  plot_["y_um"].push_back(number(t.y_um));
  plot_["e_um"].push_back(number(t.e_um));
  plot_["u_V"].push_back(number(t.u_V));
  plot_["d_hat"].push_back(number(t.d_hat));
}

json TelemetryBatcher::take(std::uint64_t& log_time_ns) {
  json b = std::move(plot_);
  for (const char* k : {"t_s", "r_um", "y_um", "e_um", "u_V", "d_hat"})
    if (!b.contains(k)) b[k] = json::array();
  b["samples"] = samples_;
  b["first_seq"] = first_seq_;
  b["last_seq"] = last_seq_;
  b["gaps"] = gaps_;
  b["stats_n"] = stats_n_;
  b["sum_abs_e_um"] = sum_abs_e_;
  b["sum_sq_e_um2"] = sum_sq_e_;
  b["max_abs_e_um"] = max_abs_e_;
  log_time_ns = last_stamp_;
  plot_ = json::object();
  samples_ = gaps_ = stats_n_ = 0;
  sum_abs_e_ = sum_sq_e_ = max_abs_e_ = 0.0;
  return b;
}

std::string message_data_frame(std::uint32_t subscription_id, std::uint64_t log_time_ns, std::string_view payload) {
  std::string f;
  f.reserve(13 + payload.size());
  f.push_back(0x01);
  put_u32(f, subscription_id);
  put_u64(f, log_time_ns);
  f.append(payload);
  return f;
}

std::string service_response_frame(std::uint32_t service_id, std::uint32_t call_id, std::string_view encoding,
                                   std::string_view payload) {
  std::string f;
  f.push_back(0x03);
  put_u32(f, service_id);
  put_u32(f, call_id);
  put_u32(f, static_cast<std::uint32_t>(encoding.size()));
  f.append(encoding);
  f.append(payload);
  return f;
}

std::optional<ServiceCall> parse_service_call(std::string_view frame, std::string& error) {
  if (frame.size() < 13 || frame[0] != 0x02) {
    error = "service call request shorter than its 13-byte header (" + std::to_string(frame.size()) + " bytes)";
    return std::nullopt;
  }
  ServiceCall c;
  c.service_id = get_u32(frame, 1);
  c.call_id = get_u32(frame, 5);
  const std::uint32_t encoding_length = get_u32(frame, 9);
  if (encoding_length > frame.size() - 13) {
    error = "service call request: encoding length " + std::to_string(encoding_length) + " exceeds the frame";
    return std::nullopt;
  }
  c.encoding = std::string(frame.substr(13, encoding_length));
  c.payload = std::string(frame.substr(13 + encoding_length));
  return c;
}

std::optional<ClientMessage> parse_client_message(std::string_view frame, std::string& error) {
  if (frame.size() < 5 || frame[0] != 0x01) {
    error = "client message shorter than its 5-byte header (" + std::to_string(frame.size()) + " bytes)";
    return std::nullopt;
  }
  return ClientMessage{get_u32(frame, 1), std::string(frame.substr(5))};
}

std::optional<ClientTopic> parse_client_topic(const std::string& topic, std::string& error) {
  const auto slash = topic.find('/', 1);
  if (topic.size() > 1 && topic[0] == '/' && slash != std::string::npos && slash > 1) {
    const std::string kind = topic.substr(slash + 1);
    if (kind == "command" || kind == "reference") return ClientTopic{topic.substr(1, slash - 1), kind};
  }
  error = "cannot publish on '" + topic.substr(0, 80) + "': clients publish only on /RIG/command and /RIG/reference";
  return std::nullopt;
}

void ClientQueue::push_data(Frame f) {
  if (data_.size() >= max_data_) {
    data_.pop_front();
    ++dropped_;
  }
  data_.push_back(std::move(f));
}

bool ClientQueue::push_protocol(Frame f) {
  protocol_.push_back(std::move(f));
  return protocol_.size() <= max_protocol_;
}

std::optional<Frame> ClientQueue::pop() {
  auto& q = protocol_.empty() ? data_ : protocol_;
  if (q.empty()) return std::nullopt;
  Frame f = std::move(q.front());
  q.pop_front();
  return f;
}

}  // namespace pvcgel::tools::serve
