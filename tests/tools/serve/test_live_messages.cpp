// The pure parts of `pvcgel serve`: Foxglove framing, the JSON encoding,
// the page's batches, and the drop-oldest client queue.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <regex>
#include <sstream>
#include <vector>

#include "daemon/control_loop.hpp"
#include "tools/serve/live_messages.hpp"

using namespace pvcgel::tools::serve;

namespace {
pvcgel_v1_Telemetry sample(std::uint64_t seq, double r, double y) {
  pvcgel_v1_Telemetry t{};
  std::snprintf(t.rig_id, sizeof t.rig_id, "rig1");
  t.seq = seq;
  t.t_s = static_cast<double>(seq) * 1e-3;
  t.r_um = r;
  t.y_um = y;
  t.e_um = r - y;
  t.state = 2;
  t.stamp_ns = static_cast<long long>(seq) * 1'000'000;
  return t;
}
}  // namespace

TEST(LiveMessages, TelemetryJsonCarriesEveryIdlFieldAndNamesAndNullForNaN) {
  auto t = sample(7, 100.0, NAN);
  t.fault = 1;
  const auto j = to_json(t);
  EXPECT_EQ(j["seq"], 7u);
  EXPECT_TRUE(j["y_um"].is_null());
  EXPECT_EQ(j["state_name"], "RUNNING");
  EXPECT_EQ(j["fault_name"], "sensor_nan");
  const auto schema = nlohmann::json::parse(telemetry_schema());
  for (const auto& [key, value] : j.items()) EXPECT_TRUE(schema["properties"].contains(key)) << key;
  EXPECT_EQ(schema["properties"].size(), j.size());
}

TEST(LiveMessages, UnknownWireValuesAreNamedNotIndexed) {
  EXPECT_EQ(state_name(200), "unknown(200)");
  EXPECT_EQ(fault_name(255), "unknown(255)");
  // Every reason the daemon has is named (the bound follows the enum, not a value written here).
  EXPECT_EQ(fault_name(static_cast<std::uint8_t>(pvcgel::daemon::FaultReason::hv_disable_failed)), "hv_disable_failed");
  const auto past_last = static_cast<std::uint8_t>(pvcgel::daemon::kFaultReasonNames.size());
  EXPECT_EQ(fault_name(past_last), "unknown(" + std::to_string(past_last) + ")");
  EXPECT_EQ(mode_name(4), "unknown(4)");
  EXPECT_EQ(reason_name(250), "unknown(250)");
  EXPECT_EQ(mode_name(3), "inverse_pid_dob_ff");
}

TEST(LiveMessages, MessageDataFrameIsLittleEndianOpcodeOne) {
  const auto f = message_data_frame(0x01020304, 0x1122334455667788ULL, "{}");
  ASSERT_EQ(f.size(), 15u);
  EXPECT_EQ(f[0], 0x01);
  EXPECT_EQ(static_cast<unsigned char>(f[1]), 0x04);
  EXPECT_EQ(static_cast<unsigned char>(f[4]), 0x01);
  EXPECT_EQ(static_cast<unsigned char>(f[5]), 0x88);
  EXPECT_EQ(static_cast<unsigned char>(f[12]), 0x11);
  EXPECT_EQ(f.substr(13), "{}");
}

TEST(LiveMessages, ServiceCallRoundTripAndTruncatedFramesAreRefused) {
  std::string frame = service_response_frame(5, 9, "json", "{\"a\":1}");
  frame[0] = 0x02;  // the request has the response's layout with opcode 2
  std::string error;
  const auto call = parse_service_call(frame, error);
  ASSERT_TRUE(call) << error;
  EXPECT_EQ(call->service_id, 5u);
  EXPECT_EQ(call->call_id, 9u);
  EXPECT_EQ(call->encoding, "json");
  EXPECT_EQ(call->payload, "{\"a\":1}");
  EXPECT_FALSE(parse_service_call(frame.substr(0, 10), error));
  frame[9] = static_cast<char>(0xff);  // encoding length beyond the frame
  EXPECT_FALSE(parse_service_call(frame, error));
  EXPECT_NE(error.find("exceeds"), std::string::npos);
}

TEST(LiveMessages, ParsesClientPublishedMessagesAndTheirTopics) {
  std::string error;
  std::string frame{'\x01', '\x07', '\x00', '\x00', '\x01'};  // channel 0x01000007, little-endian
  frame += "{\"command\":\"arm\"}";
  const auto m = parse_client_message(frame, error);
  ASSERT_TRUE(m) << error;
  EXPECT_EQ(m->channel_id, 0x01000007u);
  EXPECT_EQ(m->payload, "{\"command\":\"arm\"}");
  EXPECT_FALSE(parse_client_message(frame.substr(0, 4), error));
  EXPECT_NE(error.find("5-byte header"), std::string::npos);

  const auto command = parse_client_topic("/rig1/command", error);
  ASSERT_TRUE(command) << error;
  EXPECT_EQ(command->rig, "rig1");
  EXPECT_EQ(command->kind, "command");
  const auto reference = parse_client_topic("/lab-a/reference", error);
  ASSERT_TRUE(reference) << error;
  EXPECT_EQ(reference->rig, "lab-a");
  EXPECT_EQ(reference->kind, "reference");
  for (const char* bad : {"/rig1/telemetry", "rig1/command", "//command", "/rig1/command/x", "/command", ""}) {
    EXPECT_FALSE(parse_client_topic(bad, error)) << bad;
    EXPECT_NE(error.find("only on /RIG/command and /RIG/reference"), std::string::npos) << bad;
  }
}

TEST(LiveMessages, BatchPlotsEveryNthSampleButCountsAllAndTheirGaps) {
  TelemetryBatcher b(10);
  for (std::uint64_t s = 1; s <= 100; ++s)
    if (s != 50) b.add(sample(s, 1.0, s % 2 ? 0.5 : 1.5));  // |e| = 0.5 everywhere
  std::uint64_t log_time = 0;
  const auto j = b.take(log_time);
  EXPECT_EQ(j["samples"], 99u);
  EXPECT_EQ(j["gaps"], 1u);
  EXPECT_EQ(j["t_s"].size(), 9u);  // seq 10, 20, ... 100, but not the lost 50
  EXPECT_DOUBLE_EQ(j["sum_abs_e_um"].get<double>(), 99 * 0.5);
  EXPECT_DOUBLE_EQ(j["max_abs_e_um"].get<double>(), 0.5);
  EXPECT_EQ(log_time, 100u * 1'000'000u);
  EXPECT_TRUE(b.empty());
  EXPECT_EQ(b.take(log_time)["t_s"].size(), 0u);
}

TEST(LiveMessages, ClientQueueDropsOldestDataCountsItAndNeverDropsProtocolFrames) {
  ClientQueue q(3, 2);
  for (int i = 0; i < 5; ++i) q.push_data(Frame{std::make_shared<const std::string>(std::to_string(i)), true});
  EXPECT_TRUE(q.push_protocol(Frame{std::make_shared<const std::string>("advertise"), false}));
  EXPECT_EQ(q.dropped(), 2u);
  EXPECT_EQ(*q.pop()->data, "advertise");  // protocol first
  EXPECT_EQ(*q.pop()->data, "2");          // 0 and 1 were dropped
  EXPECT_EQ(*q.pop()->data, "3");
  EXPECT_EQ(*q.pop()->data, "4");
  EXPECT_FALSE(q.pop());
  EXPECT_TRUE(q.push_protocol(Frame{std::make_shared<const std::string>("a"), false}));
  EXPECT_TRUE(q.push_protocol(Frame{std::make_shared<const std::string>("b"), false}));
  EXPECT_FALSE(q.push_protocol(Frame{std::make_shared<const std::string>("c"), false}));  // too slow: disconnect
}

namespace {
/// Field names of `struct NAME` in the project's IDL, in order.
std::vector<std::string> idl_fields(const std::string& name) {
  std::ifstream in(std::string(PVCGEL_SOURCE_DIR) + "/daemon/dds/pvcgel_v1.idl");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string idl = ss.str();
  const auto begin = idl.find("struct " + name + " {");
  const auto end = idl.find("};", begin);
  std::vector<std::string> fields;
  const std::regex field(R"(^\s*(?:@key\s+)?[A-Za-z_][\w<>, ]*\s+(\w+)(?:\[\d+\])?;)");
  std::istringstream lines(idl.substr(begin, end - begin));
  for (std::string line; std::getline(lines, line);) {
    std::smatch m;
    if (std::regex_search(line, m, field)) fields.push_back(m[1]);
  }
  return fields;
}

void expect_schema_matches_idl(const std::string& schema_text, const std::string& idl_struct) {
  const auto props = nlohmann::json::parse(schema_text)["properties"];
  const auto fields = idl_fields(idl_struct);
  ASSERT_GT(fields.size(), 5u) << idl_struct;
  for (const auto& f : fields) EXPECT_TRUE(props.contains(f)) << idl_struct << "." << f << " missing from the schema";
  for (const auto& [key, value] : props.items()) {
    if (key.size() >= 5 && key.substr(key.size() - 5) == "_name") continue;  // the added name strings
    EXPECT_NE(std::find(fields.begin(), fields.end(), key), fields.end()) << key << " is not an IDL field of " << idl_struct;
  }
}
}  // namespace

// The schemas' fields are generated at build time from the IDL (tools/serve/idl_json_schema.py);
// this independent parse of the IDL checks the generator: every field, nothing else but the
// *_name strings, JSON types from the IDL types. (A field added to the IDL but not encoded
// by to_json fails TelemetryJsonCarriesEveryIdlFieldAndNamesAndNullForNaN and the like.)
TEST(LiveMessages, SchemasListExactlyTheIdlFields) {
  expect_schema_matches_idl(telemetry_schema(), "Telemetry");
  expect_schema_matches_idl(status_schema(), "Status");
  expect_schema_matches_idl(reply_schema(), "CommandReply");
  const auto telemetry = nlohmann::json::parse(telemetry_schema())["properties"];
  EXPECT_EQ(telemetry["y_um"]["type"], nlohmann::json::array({"number", "null"}));  // double: NaN is null
  EXPECT_EQ(telemetry["seq"]["type"], "integer");                                    // unsigned long long
  EXPECT_EQ(telemetry["high_voltage"]["type"], "boolean");
  EXPECT_EQ(telemetry["rig_id"]["type"], "string");                                  // @key string<32>
  EXPECT_EQ(telemetry["e_um"]["description"], "r - y");                              // the IDL's comment
  const auto status = nlohmann::json::parse(status_schema())["properties"];
  EXPECT_EQ(status["rejects_by_reason"]["type"], "array");                           // unsigned long [24]
}

TEST(LiveMessages, StatusAndReplyJsonCarryExactlyTheirSchemasFields) {
  pvcgel_v1_Status st{};
  pvcgel_v1_CommandReply r{};
  const std::pair<nlohmann::json, std::string> cases[] = {{to_json(st), status_schema()}, {to_json(r), reply_schema()}};
  for (const auto& [encoded, schema_text] : cases) {
    const auto props = nlohmann::json::parse(schema_text)["properties"];
    for (const auto& [key, value] : encoded.items()) EXPECT_TRUE(props.contains(key)) << key;
    EXPECT_EQ(props.size(), encoded.size()) << schema_text.substr(0, 120);
  }
}
