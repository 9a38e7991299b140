// Issue 14, item 3: the chain end to end with the real binaries, as benchmarks/effect_chain.sh runs it
// (record with pvcgeld, pvcgel diagnose, pvcgeld with the augmented model, track the paper's references),
// shorter than the benchmark: 30 s per reference, mean |e| over 10..30 s.
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
                                            PVCGEL_BINARY_DIR, "--out", out.string(), "--track-s", "30", "--settle-s",
                                            "10", "--jobs", "14"});
  const auto r = chain.wait();
  std::cout << r.out << r.err;
  ASSERT_EQ(r.exit_code, 0);

  // 1. Diagnosis names the rig's effect(s), from the recordings and the nominal model only.
  std::map<std::string, std::string> mixture;
  for (const auto& row : read_tsv(out / "diagnosis.tsv")) mixture[row.at(0)] = row.at(2);
  EXPECT_EQ(mixture["hysteresis"], "hysteresis");
  EXPECT_EQ(mixture["creep"], "creep");
  EXPECT_TRUE(mixture["both"] == "hysteresis+creep" || mixture["both"] == "creep+hysteresis") << mixture["both"];

  // 2. Tracking: the nominal and floor runs always exist; the augmented one needs the controller to read
  //    [[model.effect]] (issue 14 item 1), else pvcgeld refuses the file naming the key.
  const auto rows = read_tsv(out / "results.tsv");
  ASSERT_EQ(rows.size(), 12u);
  for (const auto& row : rows) {
    EXPECT_GT(number(row.at(3)), 0.0) << row.at(0) << " " << row.at(1) << ": no nominal run";
    EXPECT_GT(number(row.at(4)), 0.0) << row.at(1) << ": no noise-floor run";
  }
  const std::string refusal = pvcgel::test::slurp((out / "hysteresis" / "track-augmented-1hz.log").string());
  if (refusal.find("configuration error: model.effect") != std::string::npos)
    GTEST_SKIP() << "pvcgeld does not read [[model.effect]] yet: " << refusal;
  std::map<std::string, double> sum_ratio;
  for (const auto& row : rows) {
    const double diagnosed = number(row.at(2)), nominal = number(row.at(3));
    // Never worse than without the effects (5% for the run-to-run spread of the noise).
    EXPECT_LE(diagnosed, 1.05 * nominal) << row.at(0) << " " << row.at(1);
    sum_ratio[row.at(0)] += nominal / diagnosed / 4.0;
  }
  // Clearly better on each rig (mean over the four references of without / with the diagnosed effects).
  for (const auto& [rig, ratio] : sum_ratio) EXPECT_GE(ratio, 1.3) << rig;
}

}  // namespace
