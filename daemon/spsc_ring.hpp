#pragma once
/// @file
/// Bounded single-producer single-consumer lock-free ring.

#include <array>
#include <atomic>
#include <cstddef>
#include <new>
#include <optional>

namespace pvcgel::daemon {

/// Wait-free for both sides: exactly one thread pushes, exactly one pops.
/// Capacity is a power of two; storage lives inside the object (no heap), so a
/// real-time thread may push. `T` must be trivially copyable.
template <typename T, std::size_t Capacity>
class SpscRing final {
  static_assert(Capacity >= 2 && (Capacity & (Capacity - 1)) == 0, "capacity must be a power of two");
  static_assert(std::is_trivially_copyable_v<T>);

 public:
  /// Producer: false when full (the item is not stored).
  bool push(const T& item) noexcept {
    const auto head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ == Capacity) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ == Capacity) return false;
    }
    slots_[head & (Capacity - 1)] = item;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }
  /// Consumer: the oldest item, if any.
  std::optional<T> pop() noexcept {
    const auto tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return std::nullopt;
    }
    T item = slots_[tail & (Capacity - 1)];
    tail_.store(tail + 1, std::memory_order_release);
    return item;
  }
  /// Consumer: the oldest item in place (no copy), or nullptr; valid until pop_front().
  const T* front() noexcept {
    const auto tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return nullptr;
    }
    return &slots_[tail & (Capacity - 1)];
  }
  /// Consumer: drop the item front() returned.
  void pop_front() noexcept { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }
  /// Approximate number of stored items (exact when called by either side while the other is idle).
  [[nodiscard]] std::size_t size() const noexcept {
    return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire);
  }
  static constexpr std::size_t capacity() noexcept { return Capacity; }

 private:
  static constexpr std::size_t kLine = 64;
  alignas(kLine) std::atomic<std::size_t> head_{0};
  std::size_t tail_cache_ = 0;  // producer's view of tail
  alignas(kLine) std::atomic<std::size_t> tail_{0};
  std::size_t head_cache_ = 0;  // consumer's view of head
  alignas(kLine) std::array<T, Capacity> slots_{};
};

}  // namespace pvcgel::daemon
