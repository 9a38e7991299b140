#pragma once
/// @file
/// Wake-up latency and compute-time statistics of the real-time loop.

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>

namespace pvcgel::daemon {

/// Histogram with 1 us bins up to kBins us (the last bin collects the rest).
/// Written only by the real-time thread (relaxed atomics: lock-free, no
/// fences on the hot path), read by anyone.
class LatencyHistogram final {
 public:
  static constexpr int kBins = 5000;

  void add(std::int64_t ns) noexcept {
    const auto us = std::clamp<std::int64_t>(ns / 1000, 0, kBins - 1);
    bins_[static_cast<std::size_t>(us)].fetch_add(1, std::memory_order_relaxed);
    count_.fetch_add(1, std::memory_order_relaxed);
    if (ns > max_ns_.load(std::memory_order_relaxed)) max_ns_.store(ns, std::memory_order_relaxed);
  }
  [[nodiscard]] std::uint64_t count() const noexcept { return count_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::int64_t max_ns() const noexcept { return max_ns_.load(std::memory_order_relaxed); }
  /// Upper edge (us) of the bin holding quantile q in [0, 1].
  [[nodiscard]] double quantile_us(double q) const noexcept {
    const auto n = count();
    if (n == 0) return 0.0;
    const auto target = static_cast<std::uint64_t>(q * static_cast<double>(n - 1)) + 1;
    std::uint64_t acc = 0;
    for (int i = 0; i < kBins; ++i) {
      acc += bins_[static_cast<std::size_t>(i)].load(std::memory_order_relaxed);
      if (acc >= target) return i + 1.0;
    }
    return kBins;
  }

 private:
  std::array<std::atomic<std::uint64_t>, kBins> bins_{};
  std::atomic<std::uint64_t> count_{0};
  std::atomic<std::int64_t> max_ns_{0};
};

/// Everything the loop measures about its own timing.
struct LoopStatistics {
  LatencyHistogram wakeup_latency;  ///< actual - scheduled wake-up
  LatencyHistogram compute_time;    ///< wake-up to end of cycle work
  std::atomic<std::uint64_t> overruns{0};            ///< cycles that missed their deadline
  std::atomic<std::uint64_t> cycles{0};
  std::atomic<std::uint64_t> records_dropped{0};     ///< recorder ring full (must stay 0)
};

}  // namespace pvcgel::daemon
