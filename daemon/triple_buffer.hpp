#pragma once
/// @file
/// Lock-free triple buffer: latest-value exchange between one writer and one reader.

#include <array>
#include <atomic>
#include <cstdint>

namespace pvcgel::daemon {

/// The writer never waits and never overwrites what the reader is reading;
/// the reader always gets the most recent complete value. Used for status
/// snapshots (loop statistics) going from the real-time thread to others.
template <typename T>
class TripleBuffer final {
 public:
  /// Writer: publish a new value.
  void write(const T& value) noexcept {
    buffers_[write_index_] = value;
    const std::uint8_t prev = middle_.exchange(static_cast<std::uint8_t>(write_index_ | kFresh), std::memory_order_acq_rel);
    write_index_ = prev & kIndexMask;
  }
  /// Reader: the latest value (the same one again if nothing new was written).
  const T& read() noexcept {
    if (middle_.load(std::memory_order_relaxed) & kFresh) {
      const std::uint8_t prev = middle_.exchange(read_index_, std::memory_order_acq_rel);
      read_index_ = prev & kIndexMask;
    }
    return buffers_[read_index_];
  }

 private:
  static constexpr std::uint8_t kFresh = 0x4, kIndexMask = 0x3;
  std::array<T, 3> buffers_{};
  std::uint8_t write_index_ = 0, read_index_ = 1;
  std::atomic<std::uint8_t> middle_{2};
};

}  // namespace pvcgel::daemon
