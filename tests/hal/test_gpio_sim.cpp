// The libgpiod path on real kernel GPIO lines: a gpio-sim chip created through
// configfs. Needs root and the gpio-sim module; where either is missing the
// test reports itself skipped (this CI machine has no GPIO support at all).
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "control/config_error.hpp"
#include "hal/gpiod_lines.hpp"

using namespace pvcgel;
namespace fs = std::filesystem;

namespace {

const fs::path kConfigfs = "/sys/kernel/config/gpio-sim";

void write(const fs::path& p, const std::string& v) {
  std::ofstream f(p);
  f << v;
  if (!f) throw std::runtime_error("cannot write " + p.string());
}
std::string read(const fs::path& p) {
  std::ifstream f(p);
  std::string s;
  std::getline(f, s);
  return s;
}

/// A live gpio-sim chip with named lines HV_EN (0), ESTOP (1), AMP_FAULT (2).
struct SimChip {
  fs::path dev = kConfigfs / ("pvcgel-" + std::to_string(getpid()));
  std::string chip_name, sysfs;
  SimChip() {
    fs::create_directory(dev);
    fs::create_directory(dev / "bank0");
    write(dev / "bank0" / "num_lines", "4");
    const char* names[] = {"HV_EN", "ESTOP", "AMP_FAULT"};
    for (int i = 0; i < 3; ++i) {
      const auto line = dev / "bank0" / ("line" + std::to_string(i));
      fs::create_directory(line);
      write(line / "name", names[i]);
    }
    write(dev / "live", "1");
    chip_name = read(dev / "bank0" / "chip_name");
    sysfs = "/sys/devices/platform/" + read(dev / "dev_name") + "/" + chip_name;
  }
  ~SimChip() {
    std::error_code ec;
    write(dev / "live", "0");
    for (int i = 0; i < 3; ++i) fs::remove(dev / "bank0" / ("line" + std::to_string(i)), ec);
    fs::remove(dev / "bank0", ec);
    fs::remove(dev, ec);
  }
  /// Drives an input line from "outside" (the simulated wiring).
  void pull(int offset, bool high) const { write(sysfs + "/sim_gpio" + std::to_string(offset) + "/pull", high ? "pull-up" : "pull-down"); }
  [[nodiscard]] int value(int offset) const { return std::stoi(read(sysfs + "/sim_gpio" + std::to_string(offset) + "/value")); }
};

}  // namespace

TEST(GpioSim, LinesByNameEdgesAndActiveLevels) {
  if (!fs::exists(kConfigfs)) GTEST_SKIP() << "no gpio-sim in this kernel (" << kConfigfs << " missing)";
  if (geteuid() != 0) GTEST_SKIP() << "gpio-sim needs root to create a chip";
  SimChip sim;
  sim.pull(1, true);  // e-stop released (active low)
  sim.pull(2, true);  // amplifier OK (active low)
  hal::GpioConfig cfg{sim.chip_name, "HV_EN", false, "ESTOP", true, "AMP_FAULT", true};
  hal::GpiodLines lines(cfg);
  EXPECT_EQ(sim.value(0), 0) << "requested inactive";
  auto in = lines.poll();
  EXPECT_TRUE(in.ok);
  EXPECT_FALSE(in.estop_active);
  ASSERT_TRUE(lines.set_enable(true));
  EXPECT_EQ(sim.value(0), 1);
  sim.pull(1, false);  // press
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  in = lines.poll();
  EXPECT_TRUE(in.edge_seen);
  EXPECT_TRUE(in.estop_active);
  sim.pull(1, true);
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  in = lines.poll();
  EXPECT_TRUE(in.edge_seen);
  EXPECT_FALSE(in.estop_active);
  EXPECT_FALSE(lines.poll().edge_seen) << "events are drained";
  ASSERT_TRUE(lines.set_enable(false));
  EXPECT_EQ(sim.value(0), 0);
}

TEST(GpioSim, MissingLineIsAConfigErrorNamingTheKey) {
  if (!fs::exists(kConfigfs)) GTEST_SKIP() << "no gpio-sim in this kernel (" << kConfigfs << " missing)";
  if (geteuid() != 0) GTEST_SKIP() << "gpio-sim needs root to create a chip";
  SimChip sim;
  hal::GpioConfig cfg{sim.chip_name, "HV_EN", false, "NO_SUCH_LINE", true, "", true};
  try {
    hal::GpiodLines lines(cfg);
    FAIL();
  } catch (const control::ConfigError& e) {
    EXPECT_EQ(e.key(), "hal.gpio.estop_line");
  }
}

TEST(GpioSim, MissingChipIsAConfigErrorNamingTheKey) {
  // Runs everywhere: no chip of this name exists on any machine.
  hal::GpioConfig cfg{"pvcgel-no-such-chip", "HV_EN", false, "ESTOP", true, "", true};
  try {
    hal::GpiodLines lines(cfg);
    FAIL();
  } catch (const control::ConfigError& e) {
    EXPECT_EQ(e.key(), "hal.gpio.chip");
    EXPECT_NE(std::string(e.what()).find("pvcgel-no-such-chip"), std::string::npos);
  }
}
