#pragma once
/// @file
/// What `pvcgel serve` puts on the wire: the Foxglove WebSocket protocol v1
/// framing, the JSON encoding of the DDS samples with JSON schemas that list
/// the IDL's fields, the page's telemetry batches, and the per-client queue.
/// Pure computation: no sockets, no DDS, no clocks (testable on its own).

#include <nlohmann/json.hpp>

#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "pvcgel_v1.h"

namespace pvcgel::tools::serve {

/// The WebSocket subprotocol Foxglove Studio and @foxglove/ws-protocol speak.
inline constexpr const char* kSubprotocol = "foxglove.websocket.v1";

/// Wire enums by name. A value this build does not know (a newer daemon) is
/// "unknown(N)": a byte from the network never indexes an array unchecked.
std::string state_name(std::uint8_t v);
std::string fault_name(std::uint8_t v);
std::string mode_name(std::uint8_t v);
std::string reason_name(std::uint8_t v);

/// One sample as JSON: every IDL field under its IDL name, plus `state_name`,
/// `mode_name`, `fault_name` (and `reason_name`, `last_reject_reason_name`).
/// A NaN (a faulted sensor) becomes null.
nlohmann::json to_json(const pvcgel_v1_Telemetry& t);
nlohmann::json to_json(const pvcgel_v1_Status& s);
nlohmann::json to_json(const pvcgel_v1_CommandReply& r);

/// JSON schemas (draft 2020-12, as text) of the above and of the page's batch.
std::string telemetry_schema();
std::string status_schema();
std::string reply_schema();
std::string batch_schema();
/// Service request/response schemas (`/RIG/command`, `/RIG/reference`).
std::string command_request_schema();
std::string reference_request_schema();
std::string control_response_schema();

/// The page's channel: every `decimation`-th sample for the plots, plus exact
/// counts and |e| sums over *every* sample, so the page's statistics of the
/// visible window do not depend on the decimation.
class TelemetryBatcher final {
 public:
  explicit TelemetryBatcher(int decimation) : decimation_(decimation) {}
  void add(const pvcgel_v1_Telemetry& t);
  [[nodiscard]] bool empty() const noexcept { return samples_ == 0; }
  /// The batch so far (then starts a new one); `log_time_ns` = last sample's stamp.
  nlohmann::json take(std::uint64_t& log_time_ns);

 private:
  int decimation_;
  nlohmann::json plot_ = nlohmann::json::object();
  std::uint64_t samples_ = 0, gaps_ = 0, last_seq_ = 0, first_seq_ = 0, stats_n_ = 0;
  double sum_abs_e_ = 0.0, sum_sq_e_ = 0.0, max_abs_e_ = 0.0;
  std::uint64_t last_stamp_ = 0;
  bool have_seq_ = false;
};

/// Binary server frames (little-endian, as the protocol specifies).
std::string message_data_frame(std::uint32_t subscription_id, std::uint64_t log_time_ns, std::string_view payload);
std::string service_response_frame(std::uint32_t service_id, std::uint32_t call_id, std::string_view encoding,
                                   std::string_view payload);

/// A client's binary service call request (opcode 2).
struct ServiceCall {
  std::uint32_t service_id = 0;
  std::uint32_t call_id = 0;
  std::string encoding;
  std::string payload;
};
/// Parses opcode 2; nullopt and `error` set for a short or inconsistent frame.
std::optional<ServiceCall> parse_service_call(std::string_view frame, std::string& error);

/// A client's published message (opcode 1, capability clientPublish).
struct ClientMessage {
  std::uint32_t channel_id = 0;
  std::string payload;
};
/// Parses opcode 1; nullopt and `error` set for a frame shorter than its 5-byte header.
std::optional<ClientMessage> parse_client_message(std::string_view frame, std::string& error);

/// What a client may publish on: `/RIG/command` and `/RIG/reference` (the
/// requests of the services of the same names), JSON only.
struct ClientTopic {
  std::string rig;
  std::string kind;  ///< "command" or "reference"
};
/// The rig and kind of a client channel's topic; nullopt and `error` (naming
/// the topic) for any other topic.
std::optional<ClientTopic> parse_client_topic(const std::string& topic, std::string& error);

/// One outgoing frame; payloads shared between clients are not copied per client.
struct Frame {
  std::shared_ptr<const std::string> data;
  bool binary = true;
};

/// A client's outgoing frames. Data frames are bounded: when full, the oldest
/// is dropped and counted, so a stalled client costs the producer nothing.
/// Protocol frames (advertise, status, service responses) are never dropped;
/// a client that lets more than `max_protocol` of them pile up is too slow to keep.
class ClientQueue final {
 public:
  explicit ClientQueue(std::size_t max_data = 4096, std::size_t max_protocol = 1024)
      : max_data_(max_data), max_protocol_(max_protocol) {}
  void push_data(Frame f);
  /// @return false when the protocol backlog is over its bound (disconnect the client).
  bool push_protocol(Frame f);
  /// The next frame, protocol frames first.
  std::optional<Frame> pop();
  [[nodiscard]] std::uint64_t dropped() const noexcept { return dropped_; }
  [[nodiscard]] std::size_t size() const noexcept { return data_.size() + protocol_.size(); }

 private:
  std::size_t max_data_, max_protocol_;
  std::deque<Frame> data_, protocol_;
  std::uint64_t dropped_ = 0;
};

}  // namespace pvcgel::tools::serve
