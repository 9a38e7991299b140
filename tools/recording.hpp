#pragma once
/// @file
/// Reading the recording format (defined once, with its writer, in daemon/recorder.hpp).

#include <map>
#include <string>
#include <vector>

namespace pvcgel::tools {

/// A recording in memory: numeric columns by name, text columns by name, and
/// the `# key: value` header lines.
struct Recording {
  std::string path;
  std::map<std::string, std::string> header;
  std::map<std::string, std::vector<double>> numeric;
  std::map<std::string, std::vector<std::string>> text;
  long skipped_rows = 0;  ///< rows dropped for a non-finite t_s, u_V or y_um (counted, reported)
  long invalid_rows = 0;  ///< rows with a non-finite t_s, u_V or y_um (kept or skipped)
  long truncated_rows = 0;  ///< a last line cut by a crash (no newline or too few fields): skipped, counted
  double sample_time_s = 0.0;

  [[nodiscard]] size_t rows() const { return numeric.at("t_s").size(); }
  [[nodiscard]] const std::vector<double>& col(const std::string& name) const;
  [[nodiscard]] bool has(const std::string& name) const { return numeric.count(name) || text.count(name); }
};

/// Bounds beyond which a recorded value cannot be a measurement of a gel rig:
/// 10x the amplifier's 0..1000 V, and 1 m of displacement (the sim's injected
/// out-of-range sensor reads exactly 1e6 um and stays readable).
inline constexpr double kMaxPhysicalVoltage_V = 1e4;
inline constexpr double kMaxPhysicalDisplacement_um = 1e6;

/// Reads and checks a recording: the header must have at least t_s, u_V and
/// y_um; time must increase uniformly (1% tolerance). Columns that parse as
/// numbers everywhere are numeric, others text. A last line cut by a crash
/// (SIGKILL) is skipped and counted in `truncated_rows`, never fatal; a finite
/// u_V or y_um beyond the physical bounds above is an error naming file:line.
/// @param keep_invalid_rows  keep rows whose u_V or y_um is not finite (a
///        faulted sensor is recorded as NaN); t_s must be finite regardless
/// @throws std::runtime_error naming the file, line and reason.
Recording read_recording(const std::string& path, bool keep_invalid_rows = false);

}  // namespace pvcgel::tools
