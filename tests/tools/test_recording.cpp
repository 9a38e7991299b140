// The recording reader shared by show, diagnose and ident: what a crash leaves
// (a cut last line) is skipped and counted; non-physical values are refused
// naming file:line.
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "tools/recording.hpp"

namespace {

std::string write(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + "rec_" + name + ".csv";
  std::ofstream(path) << text;
  return path;
}

const std::string kHeader = "# rate_hz: 1000\nt_s,u_V,y_um\n";

}  // namespace

TEST(Recording, ACutLastLineIsSkippedAndCountedNeverFatal) {
  const auto rec = pvcgel::tools::read_recording(write("cut", kHeader + "0.000,10,1\n0.001,11,1.1\n0.002,12,1.2\n0.003,1"));
  EXPECT_EQ(rec.rows(), 3u);
  EXPECT_EQ(rec.truncated_rows, 1);
  const auto whole = pvcgel::tools::read_recording(write("whole", kHeader + "0.000,10,1\n0.001,11,1.1\n0.002,12,1.2\n"));
  EXPECT_EQ(whole.rows(), 3u);
  EXPECT_EQ(whole.truncated_rows, 0);
}

TEST(Recording, NonPhysicalValuesAreRefusedNamingFileAndLine) {
  const auto path = write("huge", kHeader + "0.000,10,1\n0.001,1e308,1.1\n0.002,12,1.2\n");
  try {
    pvcgel::tools::read_recording(path);
    FAIL() << "u_V = 1e308 accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path + ":4: u_V = 1e308 is not physical"), std::string::npos) << e.what();
  }
  EXPECT_THROW(pvcgel::tools::read_recording(write("far", kHeader + "0.000,10,1\n0.001,11,1e300\n0.002,12,1.2\n")),
               std::runtime_error);
  // The sim's injected out-of-range sensor (exactly 1e6 um) is a reading, not corruption.
  EXPECT_NO_THROW(pvcgel::tools::read_recording(write("edge", kHeader + "0.000,10,1\n0.001,11,1e6\n0.002,12,1.2\n")));
}
