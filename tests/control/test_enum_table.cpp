// The checked name table every named enum uses (control/enum_table.hpp).
#include <gtest/gtest.h>

#include "control/controller.hpp"
#include "control/enum_table.hpp"

namespace {

// A table that does not start at 0, as the DDS command kinds do.
enum class Gear : std::uint8_t { first = 1, second, third };
constexpr auto kGearNames = pvcgel::enum_table<Gear::first, Gear::third>({"first", "second", "third"});
constexpr const auto& names_of(Gear) noexcept { return kGearNames; }

// Everything is usable at compile time (the loop's path may use it).
static_assert(kGearNames.to_string(Gear::second) == "second");
static_assert(pvcgel::from_wire<Gear>(3) == Gear::third);
static_assert(!pvcgel::from_wire<Gear>(0).has_value());
static_assert(pvcgel::parse_enum<Gear>("first") == Gear::first);
static_assert(kGearNames.enumerators() == std::array{Gear::first, Gear::second, Gear::third});

}  // namespace

TEST(EnumTable, AnOffsetTableMapsNamesAndWireValuesBothWaysAndRefusesTheRest) {
  for (std::uint8_t v = 1; v <= 3; ++v) {
    const auto g = pvcgel::from_wire<Gear>(v);
    ASSERT_TRUE(g.has_value()) << int{v};
    EXPECT_EQ(pvcgel::to_wire(*g), v);
    EXPECT_EQ(pvcgel::parse_enum<Gear>(kGearNames.to_string(*g)), g);
  }
  for (const int v : {0, 4, 200, 255}) EXPECT_FALSE(pvcgel::from_wire<Gear>(static_cast<std::uint8_t>(v)).has_value()) << v;
  EXPECT_FALSE(pvcgel::parse_enum<Gear>("fourth").has_value());
  EXPECT_FALSE(pvcgel::parse_enum<Gear>("").has_value());
  EXPECT_FALSE(pvcgel::parse_enum<Gear>("First").has_value()) << "names are exact";
  // Only a cast can make a value outside the table; its name is "?", never a read past the table.
  EXPECT_EQ(kGearNames.to_string(static_cast<Gear>(9)), "?");
  EXPECT_EQ(kGearNames.to_string(static_cast<Gear>(0)), "?");
}

TEST(EnumTable, ControllerModesRoundTripAndUnknownWireValuesAreRefused) {
  for (const auto m : pvcgel::control::kAllModes) {
    EXPECT_EQ(pvcgel::control::parse_mode(pvcgel::control::to_string(m)), m);
    EXPECT_EQ(pvcgel::parse_enum<pvcgel::control::ControllerMode>(pvcgel::control::to_string(m)), m);
    EXPECT_EQ(pvcgel::from_wire<pvcgel::control::ControllerMode>(pvcgel::to_wire(m)), m);
  }
  EXPECT_EQ(pvcgel::control::kControllerModeNames.size(), pvcgel::control::kAllModes.size());
  EXPECT_FALSE(pvcgel::from_wire<pvcgel::control::ControllerMode>(4).has_value());
  EXPECT_FALSE(pvcgel::from_wire<pvcgel::control::ControllerMode>(255).has_value());
}
