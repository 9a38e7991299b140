#pragma once
/// @file
/// The recording format, defined once: written here (by pvcgeld's --record,
/// `pvcgel record` and `pvcgel ident`'s experiments) and read by tools/recording.*.

#include <array>
#include <chrono>
#include <cstdio>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "daemon/control_loop.hpp"

namespace pvcgel::daemon {

/// The `# key: value` lines after the first, in order.
using RecordingHeader = std::vector<std::pair<std::string, std::string>>;

/// The format's fixed lines:
/// ```
/// # pvcgel-recording: 1
/// # rate_hz: 1000
/// # ... (more `# key: value` lines)
/// # convention: ...
/// t_s,u_V,y_um,r_um,e_um,d_hat,mode,state,fault,hv,latency_us
/// ```
/// Row k: `y_um` measured at the start of cycle k (`t_s`), then `u_V` applied
/// and held until cycle k+1 (zero-order hold). `mode` is the controller mode,
/// or `open_loop` while the loop plays voltage setpoints.
inline constexpr std::string_view kRecordingMagic = "# pvcgel-recording: 1";
inline constexpr std::string_view kRecordingConvention =
    "# convention: row k holds y_um measured at the start of cycle k (t_s) and the u_V then applied and held until "
    "cycle k+1 (zero-order hold)";
inline constexpr std::string_view kRecordingColumns = "t_s,u_V,y_um,r_um,e_um,d_hat,mode,state,fault,hv,latency_us";
/// The columns a reader needs (a hand-made or external recording may have only these).
inline constexpr std::array<const char*, 3> kRecordingRequiredColumns{"t_s", "u_V", "y_um"};

/// Writes loop records to a recording, off the real-time thread.
class Recorder final {
 public:
  /// Opens the file (creating missing parent directories: see created_directory())
  /// and writes the header. @throws std::runtime_error naming the path.
  Recorder(const std::string& path, const RecordingHeader& header);
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
  /// The directory the constructor had to create for the file (empty when it existed), for the caller to report.
  [[nodiscard]] const std::string& created_directory() const noexcept { return created_directory_; }

 private:
  std::FILE* file_ = nullptr;
  std::chrono::steady_clock::time_point last_flush_ = std::chrono::steady_clock::now();
  std::string path_, created_directory_;
  std::uint64_t rows_ = 0, gaps_ = 0, next_seq_ = 0;
};

}  // namespace pvcgel::daemon
