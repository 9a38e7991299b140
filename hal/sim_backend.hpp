#pragma once
/// @file
/// The `sim` HAL backend: the simulated rig, with faults injected on command.

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>

#include "control/simulated_rig.hpp"
#include "hal/hal.hpp"

namespace pvcgel::hal {

/// Faults the sim backend can inject, so every safety path is testable without hardware.
enum class SimFault : std::uint8_t {
  none,
  sensor_nan,           ///< the sensor returns NaN
  sensor_stuck,         ///< the sensor repeats its last value exactly
  sensor_out_of_range,  ///< the sensor returns an impossible displacement
  sensor_dropout,       ///< reads time out
  amplifier_fault,      ///< the amplifier reports a fault
  write_failed,         ///< amplifier writes get an invalid reply; the amplifier keeps its last output
  write_timeout,        ///< amplifier writes time out; the amplifier keeps its last output
  hv_enable_failed,     ///< enabling high voltage fails (it stays off)
};

inline constexpr auto kSimFaultNames = enum_table<SimFault::none, SimFault::hv_enable_failed>(
    {"none", "sensor_nan", "sensor_stuck", "sensor_out_of_range", "sensor_dropout", "amplifier_fault", "write_failed",
     "write_timeout", "hv_enable_failed"});
constexpr const auto& names_of(SimFault) noexcept { return kSimFaultNames; }
/// Name of a fault ("sensor_nan", ...); parse_enum<SimFault> is the inverse.
constexpr std::string_view to_string(SimFault f) noexcept { return kSimFaultNames.to_string(f); }

/// Wraps control::SimulatedRig. Time advances one sample per write_voltage().
/// With high voltage disabled the amplifier output is 0 V whatever is written.
class SimBackend final : public Hal {
 public:
  explicit SimBackend(const control::SimRigConfig& config);

  HalStatus read_displacement(double& y_um) noexcept override;
  HalStatus write_voltage(double voltage_V) noexcept override;
  HalStatus set_high_voltage(bool enabled) noexcept override;
  [[nodiscard]] HalHealth health() const noexcept override;
  [[nodiscard]] std::string_view name() const noexcept override { return "sim"; }

  /// Inject a fault now (any thread; lock-free).
  void inject(SimFault f) noexcept { fault_.store(f, std::memory_order_relaxed); }
  /// Inject a fault when simulated time reaches t_s (set before the loop starts).
  void schedule(SimFault f, double t_s) noexcept {
    scheduled_fault_ = f;
    scheduled_at_samples_ = static_cast<std::int64_t>(t_s / rig_.config().sample_time_s);
  }
  /// Simulated time in samples.
  [[nodiscard]] std::int64_t samples() const noexcept { return samples_; }
  /// True displacement (for tests).
  [[nodiscard]] double true_displacement_um() const noexcept { return rig_.true_displacement_um(); }

 private:
  control::SimulatedRig rig_;
  std::atomic<SimFault> fault_{SimFault::none};
  SimFault scheduled_fault_ = SimFault::none;
  std::int64_t scheduled_at_samples_ = -1;
  std::int64_t samples_ = 0;
  double last_reading_ = 0.0;
  bool hv_enabled_ = false;
  double applied_V_ = 0.0;  // what the amplifier holds (a failed write leaves it)
  std::atomic<std::uint64_t> reads_{0}, writes_{0}, timeouts_{0}, invalid_{0}, device_faults_{0};
  std::atomic<bool> hv_flag_{false}, amp_fault_flag_{false};
};

}  // namespace pvcgel::hal
