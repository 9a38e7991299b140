// The one recording writer (daemon/recorder.hpp): its header, its rows, and
// what it does with a missing directory.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <unistd.h>

#include "daemon/recorder.hpp"

using namespace pvcgel::daemon;
namespace fs = std::filesystem;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) / (name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  return dir;
}

}  // namespace

TEST(Recorder, WritesTheFormatsHeaderAndOneRowPerRecordWithOpenLoopInVoltageMode) {
  const fs::path dir = fresh_dir("recorder_format");
  fs::create_directories(dir);
  const fs::path file = dir / "r.csv";
  {
    Recorder r(file.string(), {{"rate_hz", "1000"}, {"source", "test"}});
    EXPECT_TRUE(r.created_directory().empty()) << "the directory existed";
    CycleRecord rec;
    rec.seq = 7;
    rec.t_s = 0.5;
    rec.u_V = 12.5;
    rec.y_um = 3.25;
    rec.state = LoopState::running;
    r.write(rec);
    rec.seq = 9;  // one cycle missing
    rec.target = LoopTarget::voltage;
    rec.fault = FaultReason::sensor_nan;
    r.write(rec);
    r.finish();
    EXPECT_EQ(r.rows(), 2u);
    EXPECT_EQ(r.gaps(), 1u);
  }
  const std::string text = slurp(file);
  EXPECT_EQ(text.rfind(std::string(kRecordingMagic) + "\n# rate_hz: 1000\n# source: test\n", 0), 0u) << text;
  EXPECT_NE(text.find(std::string(kRecordingConvention) + "\n" + std::string(kRecordingColumns) + "\n"), std::string::npos);
  EXPECT_NE(text.find("0.5000,12.500000,3.2500,0.0000,0.0000,0,pid,RUNNING,none,0,0.0\n"), std::string::npos) << text;
  EXPECT_NE(text.find(",open_loop,RUNNING,sensor_nan,"), std::string::npos) << text;
}

TEST(Recorder, AMissingDirectoryIsCreatedAndReportedAnUncreatableOneIsAnErrorNamingIt) {
  const fs::path dir = fresh_dir("recorder_missing");
  const fs::path file = dir / "sub" / "r.csv";
  {
    Recorder r(file.string(), {});
    EXPECT_EQ(r.created_directory(), (dir / "sub").string());
    r.finish();
  }
  EXPECT_TRUE(fs::exists(file));
  // A directory below a regular file cannot be created.
  const fs::path blocked = dir / "sub" / "r.csv" / "x" / "r.csv";
  try {
    Recorder r(blocked.string(), {});
    FAIL() << "no error for " << blocked;
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot create directory '" + (dir / "sub" / "r.csv" / "x").string() + "'"),
              std::string::npos)
        << e.what();
  }
}
