#pragma once
/// @file
/// The last thing between the controller and the amplifier.

#include <algorithm>

namespace pvcgel::control {

/// Clamps the voltage command to [min, max] (never wider than 0..1000 V,
/// checked at configuration) and optionally limits its slew rate. The
/// controller feeds the returned, applied value back to the PID and the DOB.
class OutputStage final {
 public:
  OutputStage() = default;
  /// @param slew_V_per_s  0 disables the slew limit
  OutputStage(double min_V, double max_V, double slew_V_per_s, double Ts_s)
      : min_V_(min_V), max_V_(max_V), max_step_V_(slew_V_per_s > 0.0 ? slew_V_per_s * Ts_s : 0.0) {}

  /// Applied voltage for the requested one. Real-time safe; NaN maps to min.
  double apply(double request_V) noexcept {
    double u = request_V >= min_V_ ? std::min(request_V, max_V_) : min_V_;  // NaN -> min
    if (max_step_V_ > 0.0) u = std::clamp(u, last_V_ - max_step_V_, last_V_ + max_step_V_);
    return last_V_ = u;
  }
  /// Last applied voltage.
  [[nodiscard]] double last_V() const noexcept { return last_V_; }
  /// Set the remembered previous output (start-up, bumpless restarts).
  void reset(double V) noexcept { last_V_ = std::clamp(V, min_V_, max_V_); }
  [[nodiscard]] double min_V() const noexcept { return min_V_; }
  [[nodiscard]] double max_V() const noexcept { return max_V_; }

 private:
  double min_V_ = 0.0, max_V_ = 0.0, max_step_V_ = 0.0, last_V_ = 0.0;
};

}  // namespace pvcgel::control
