#include "daemon/spsc_ring.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <thread>

using pvcgel::daemon::SpscRing;

TEST(SpscRing, KeepsOrderAndReportsFull) {
  SpscRing<int, 8> ring;
  for (int i = 0; i < 8; ++i) EXPECT_TRUE(ring.push(i));
  EXPECT_FALSE(ring.push(99)) << "a full ring must refuse, not overwrite";
  EXPECT_EQ(ring.size(), 8u);
  for (int i = 0; i < 8; ++i) {
    auto v = ring.pop();
    ASSERT_TRUE(v.has_value());
    EXPECT_EQ(*v, i);
  }
  EXPECT_FALSE(ring.pop().has_value());
}

TEST(SpscRing, ConcurrentProducerConsumerLosesNothing) {
  auto ring = std::make_unique<SpscRing<std::uint64_t, 1024>>();
  constexpr std::uint64_t kItems = 2'000'000;
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kItems;)
      if (ring->push(i)) ++i;
  });
  std::uint64_t expected = 0;
  while (expected < kItems) {
    if (auto v = ring->pop()) {
      ASSERT_EQ(*v, expected) << "items must arrive once, in order";
      ++expected;
    }
  }
  producer.join();
  EXPECT_FALSE(ring->pop().has_value());
}
