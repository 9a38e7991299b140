#pragma once
/// @file
/// Writes every cycle of the loop to a CSV recording, off the real-time thread.

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "daemon/realtime_thread.hpp"

namespace pvcgel::daemon {

/// The recording format the tools read:
/// ```
/// # pvcgel-recording: 1
/// # rate_hz: 1000
/// # ... (more `# key: value` lines)
/// t_s,u_V,y_um,r_um,e_um,d_hat,mode,state,fault,hv,latency_us
/// ```
/// Row k: `y_um` measured at the start of cycle k (`t_s`), then `u_V` applied
/// and held until cycle k+1 (zero-order hold).
class Recorder final {
 public:
  /// Opens the file and writes the header. @throws std::runtime_error naming the path.
  Recorder(const std::string& path, const std::vector<std::pair<std::string, std::string>>& header);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  /// Append one row (non-RT thread). Checks sequence numbers.
  void write(const CycleRecord& r);
  /// Flush if about 100 ms passed since the last flush, so a crash loses at most that much.
  void flush_if_due();
  /// Flush everything. @throws std::runtime_error naming the file if writing failed.
  void finish();
  /// Rows written.
  [[nodiscard]] std::uint64_t rows() const noexcept { return rows_; }
  /// Missing sequence numbers seen (must be 0).
  [[nodiscard]] std::uint64_t gaps() const noexcept { return gaps_; }

 private:
  std::FILE* file_ = nullptr;
  std::chrono::steady_clock::time_point last_flush_ = std::chrono::steady_clock::now();
  std::string path_;
  std::uint64_t rows_ = 0, gaps_ = 0, next_seq_ = 0;
};

}  // namespace pvcgel::daemon
