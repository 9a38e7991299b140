// Issue 14, item 3: the chain end to end with the real binaries, as benchmarks/effect_chain.sh runs it
// (record with pvcgeld, pvcgel diagnose, pvcgeld with the augmented model, track the paper's references),
// shorter than the benchmark: 20 s per reference, mean |e| from 8 s on.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "support/subprocess.hpp"

namespace fs = std::filesystem;

namespace {

using Table = std::vector<std::vector<std::string>>;

/// Tab-separated rows after the header.
Table read_tsv(const fs::path& path) {
  std::ifstream in(path);
  Table rows;
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream s(line);
    for (std::string cell; std::getline(s, cell, '\t');) cells.push_back(cell);
    rows.push_back(cells);
  }
  return rows;
}

/// "n/a" (a run that did not happen) is NaN, so every comparison with it fails.
double number(const std::string& s) { return s == "n/a" ? NAN : std::stod(s); }

TEST(EffectChainE2E, DiagnosisNamesTheEffectsAndTheAugmentedModelTracksBetterOnThreeRigs) {
  const fs::path out = fs::path(::testing::TempDir()) / ("effect_chain_" + std::to_string(getpid()));
  fs::remove_all(out);
  pvcgel::test::Process chain("/bin/bash", {std::string(PVCGEL_SOURCE_DIR) + "/benchmarks/effect_chain.sh", "--build",
                                            PVCGEL_BINARY_DIR, "--out", out.string(), "--track-s", "20", "--settle-s",
                                            "8", "--jobs", "14"});
  const auto r = chain.wait();
  std::cout << r.out << r.err;
  ASSERT_EQ(r.exit_code, 0);

  // 1. Diagnosis names the rig's effect(s), from the recordings and the nominal model only.
  std::map<std::string, std::string> mixture;
  for (const auto& row : read_tsv(out / "diagnosis.tsv")) mixture[row.at(0)] = row.at(2);
  EXPECT_EQ(mixture["hysteresis"], "hysteresis");
  EXPECT_EQ(mixture["creep"], "creep");
  EXPECT_TRUE(mixture["both"] == "hysteresis+creep" || mixture["both"] == "creep+hysteresis") << mixture["both"];

  // 2. Tracking (inverse_pid_dob_ff): the nominal and floor runs always exist; the augmented one needs the
  //    controller to read [[model.effect]] (issue 14 item 1), else pvcgeld refuses the file naming the key.
  const auto rows = read_tsv(out / "results.tsv");
  ASSERT_EQ(rows.size(), 12u);
  for (const auto& row : rows) {
    EXPECT_GT(number(row.at(4)), 0.0) << row.at(1) << " " << row.at(2) << ": no nominal run";
    EXPECT_GT(number(row.at(5)), 0.0) << row.at(2) << ": no noise-floor run";
  }
  const std::string log =
      pvcgel::test::slurp((out / "hysteresis" / "track-augmented-inverse_pid_dob_ff-1hz.log").string());
  if (log.find("configuration error: model.effect") != std::string::npos)
    GTEST_SKIP() << "pvcgeld does not read [[model.effect]] yet: " << log;
  int with_something_to_gain = 0;
  for (const auto& row : rows) {
    const double diagnosed = number(row.at(3)), nominal = number(row.at(4)), floor = number(row.at(5));
    const std::string what = row.at(1) + " " + row.at(2);
    // The target, and never worse than without the effects (5%: run-to-run spread of the noise).
    EXPECT_LE(diagnosed, 1.5 * floor) << what;
    EXPECT_LE(diagnosed, 1.05 * nominal) << what;
    // inverse_pid_dob_ff alone (DOB and learned inverse) already keeps most references within 1.1x the floor;
    // where the nominal model leaves 15% or more above it, the diagnosed effects must remove at least half of that.
    if (nominal >= 1.15 * floor) {
      ++with_something_to_gain;
      EXPECT_LE(diagnosed - floor, 0.5 * (nominal - floor)) << what;
    }
  }
  EXPECT_GE(with_something_to_gain, 1) << "no reference where the effects cost the nominal model 15% over the floor";
  // About 60 MB of recordings: kept only when something failed, to look at.
  if (!HasFailure()) fs::remove_all(out);
}

}  // namespace
