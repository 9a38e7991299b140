#include "tools/parallel_for.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <vector>

namespace pvcgel::tools {
namespace {

TEST(ParallelFor, RunsEveryTaskOnceOnAnyNumberOfThreads) {
  for (int threads : {1, 2, 7}) {
    std::vector<std::atomic<int>> runs(23);
    parallel_for(runs.size(), threads, [&](std::size_t i) { ++runs[i]; });
    for (const auto& r : runs) EXPECT_EQ(r.load(), 1) << threads << " threads";
  }
}

TEST(ParallelFor, ATaskThatThrowsIsRethrownAfterTheOthersRan) {
  std::atomic<int> ran{0};
  EXPECT_THROW(parallel_for(10, 3, [&](std::size_t i) {
                 ++ran;
                 if (i == 4) throw std::runtime_error("task 4");
               }),
               std::runtime_error);
  EXPECT_EQ(ran.load(), 10);
}

}  // namespace
}  // namespace pvcgel::tools
