// Every named enum of the loop, the DDS interface and the HAL: its table
// round-trips every enumerator through to_string, parse and from_wire, and
// refuses values and names it does not have.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "daemon/control_loop.hpp"
#include "daemon/dds/dds_messages.hpp"
#include "daemon/input_validation.hpp"
#include "hal/modbus_backend.hpp"
#include "hal/sim_backend.hpp"

using namespace pvcgel;

namespace {

template <typename E>
class EnumNames : public ::testing::Test {};

using NamedEnums =
    ::testing::Types<daemon::LoopState, daemon::FaultReason, daemon::RejectReason, daemon::CommandKind,
                     daemon::StaleSetpointPolicy, daemon::LoopTarget, daemon::SetpointSegment::Kind,
                     daemon::SetpointSegment::Timing, control::ControllerMode, hal::SimFault, hal::WordOrder,
                     hal::HalStatus, hal::ModbusConfig::Transport>;
TYPED_TEST_SUITE(EnumNames, NamedEnums);

}  // namespace

TYPED_TEST(EnumNames, EveryEnumeratorRoundTripsAndUnknownValuesAreRefused) {
  using E = TypeParam;
  const auto& table = names_of(E{});
  const unsigned first = to_wire(table.first());
  std::set<std::string> seen;
  for (unsigned v = first; v < first + table.size(); ++v) {
    const auto e = from_wire<E>(static_cast<std::uint8_t>(v));
    ASSERT_TRUE(e.has_value()) << v;
    EXPECT_EQ(to_wire(*e), v);
    const std::string name(table.to_string(*e));
    EXPECT_FALSE(name.empty() || name == "?") << v;
    EXPECT_TRUE(seen.insert(name).second) << "name '" << name << "' twice";
    EXPECT_EQ(parse_enum<E>(name), e) << name;
  }
  if (first > 0) {
    EXPECT_FALSE(from_wire<E>(static_cast<std::uint8_t>(first - 1)).has_value());
  }
  EXPECT_FALSE(from_wire<E>(static_cast<std::uint8_t>(first + table.size())).has_value());
  EXPECT_FALSE(from_wire<E>(255).has_value());
  EXPECT_FALSE(parse_enum<E>("no_such_name").has_value());
}

TEST(EnumNames, TheNamesOnTheInterfaceAreTheDocumentedOnes) {
  // Spot checks of names that are part of the interface (logs, recordings, the client, the README).
  EXPECT_EQ(daemon::to_string(daemon::LoopState::ramp_down), "RAMP_DOWN");
  EXPECT_EQ(daemon::to_string(daemon::FaultReason::hv_disable_failed), "hv_disable_failed");
  EXPECT_EQ(daemon::to_string(daemon::RejectReason::busy), "busy");
  EXPECT_EQ(daemon::to_string(daemon::CommandKind::set_mode), "mode");
  EXPECT_FALSE(from_wire<daemon::CommandKind>(0).has_value()) << "0 is not a command";
  EXPECT_EQ(hal::to_string(hal::SimFault::write_timeout), "write_timeout");
  EXPECT_EQ(hal::to_string(hal::HalStatus::invalid_reply), "invalid_reply");
}

TEST(EnumNames, AClientNamesTheFieldAndTheValueOfAnUnknownWireByte) {
  try {
    (void)dds::checked_from_wire<daemon::LoopState>(200, "Status.state");
    FAIL() << "200 is no loop state";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()),
              "Status.state = 200 is not a value this program knows (0 DISABLED, 1 ARMED, 2 RUNNING, 3 RAMP_DOWN, 4 "
              "FAULT): a daemon of another version, or a corrupt message");
  }
  pvcgel_v1_Telemetry t{};
  t.fault = 99;
  EXPECT_THROW(
      {
        try {
          (void)dds::to_cycle_record(t);
        } catch (const std::runtime_error& e) {
          EXPECT_NE(std::string(e.what()).find("Telemetry.fault = 99"), std::string::npos) << e.what();
          throw;
        }
      },
      std::runtime_error);
}
