#pragma once
/// @file
/// Built-in setpoint sources: analytic references and CSV files.

#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "control/reference_signal.hpp"
#include "daemon/input_validation.hpp"

namespace pvcgel::daemon {

/// A reference r(t) known ahead of time, so the loop can read its preview.
/// Specs: `hold:R`, `sine:OFFSET,AMPLITUDE,FREQ_HZ`,
/// `multisine:OFFSET,A1,F1[,A2,F2...]`, `csv:FILE` (columns `t_s,r_um`,
/// strictly increasing t, linear interpolation, the last value held after the
/// end), and the paper's `paper-0.1hz`, `paper-0.5hz`, `paper-1hz`, `paper-multi`.
class Trajectory final {
 public:
  /// @throws control::ConfigError (key "trajectory") naming the spec, file and line at fault.
  static Trajectory parse(std::string_view spec);

  /// Refuses a trajectory the `[setpoints]` limits would refuse over DDS: range,
  /// step between samples, slope. @throws control::ConfigError (key "trajectory")
  /// naming the value, the limit and (CSV) the file and line.
  void check_limits(const SetpointLimits& limits) const;

  /// r(t) in um; t may exceed the end (the last value is held). Real-time safe.
  [[nodiscard]] double at(double t_s) const noexcept;
  /// Time after which the source has no new samples (infinite for analytic ones).
  [[nodiscard]] double end_s() const noexcept { return end_s_; }
  /// The spec it was made from.
  [[nodiscard]] const std::string& spec() const noexcept { return spec_; }

 private:
  // Configuration time; they throw control::ConfigError.
  void parse_analytic(const std::string& kind, const std::string& args);
  void read_csv(const std::string& path);

  std::string spec_;
  control::MultiSine analytic_{};
  std::vector<double> t_, r_;  // CSV samples (filled at configuration time only)
  std::vector<int> line_;      // CSV line of each sample
  double end_s_ = std::numeric_limits<double>::infinity();
};

}  // namespace pvcgel::daemon
