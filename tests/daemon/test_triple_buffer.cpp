#include "daemon/triple_buffer.hpp"

#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <thread>

using pvcgel::daemon::TripleBuffer;

TEST(TripleBuffer, ReaderSeesLatestValue) {
  TripleBuffer<int> b;
  b.write(1);
  b.write(2);
  EXPECT_EQ(b.read(), 2);
  EXPECT_EQ(b.read(), 2) << "reading again without a write returns the same value";
  b.write(3);
  EXPECT_EQ(b.read(), 3);
}

TEST(TripleBuffer, ConcurrentReadsAreNeverTorn) {
  // Each value is an array filled with one number: a torn read would mix two.
  using Snapshot = std::array<std::uint64_t, 16>;
  TripleBuffer<Snapshot> b;
  std::atomic<bool> done{false};
  std::thread writer([&] {
    for (std::uint64_t i = 1; i <= 500'000; ++i) {
      Snapshot s;
      s.fill(i);
      b.write(s);
    }
    done = true;
  });
  std::uint64_t last = 0;
  while (!done) {
    const Snapshot& s = b.read();
    for (auto v : s) ASSERT_EQ(v, s[0]) << "torn read";
    ASSERT_GE(s[0], last) << "values must never go back in time";
    last = s[0];
  }
  writer.join();
  EXPECT_EQ(b.read()[0], 500'000u);
}
