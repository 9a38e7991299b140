#pragma once
/// @file
/// A HAL decorator that adds the GPIO high-voltage interlock to any backend.

#include <atomic>
#include <memory>
#include <string>

#include "hal/gpio_lines.hpp"
#include "hal/hal.hpp"

namespace pvcgel::hal {

/// Wraps a backend. The HV-enable line is asserted only when the loop enables
/// high voltage and the inputs are quiet; it is deasserted FIRST (before the
/// backend is told anything) on an e-stop or amplifier-fault edge or level, on
/// a broken link, on a garbage or exception reply, and after
/// `trip_after_timeouts` consecutive read timeouts. A trip latches: until the
/// loop disables and re-enables high voltage with quiet inputs, write_voltage()
/// returns HalStatus::device_fault (the loop's amplifier_fault), within the cycle
/// the edge was polled in. The inputs are polled once per cycle in read_displacement().
class InterlockedHal final : public Hal {
 public:
  /// Drives the enable line inactive at once. `lines` must be non-null.
  InterlockedHal(std::unique_ptr<Hal> inner, std::unique_ptr<GpioLines> lines, int trip_after_timeouts);
  /// Deasserts HV enable, then destroys the backend (which writes 0 V).
  ~InterlockedHal() override;

  HalStatus read_displacement(double& y_um) noexcept override;
  HalStatus write_voltage(double voltage_V) noexcept override;
  HalStatus set_high_voltage(bool enabled) noexcept override;
  [[nodiscard]] HalHealth health() const noexcept override;
  [[nodiscard]] std::string_view name() const noexcept override { return name_; }

  /// True while a trip is latched (any thread).
  [[nodiscard]] bool tripped() const noexcept { return tripped_flag_.load(std::memory_order_relaxed); }
  /// The wrapped backend.
  [[nodiscard]] Hal& inner() noexcept { return *inner_; }

 private:
  void trip() noexcept;
  void check_inner(HalStatus s) noexcept;

  std::unique_ptr<Hal> inner_;
  std::unique_ptr<GpioLines> lines_;
  std::string name_;
  int trip_after_timeouts_;
  int consecutive_timeouts_ = 0;
  bool enabled_ = false;  // the loop's wish
  bool tripped_ = false;
  std::atomic<bool> line_flag_{false}, tripped_flag_{false};
  std::atomic<std::uint64_t> trips_{0};
};

}  // namespace pvcgel::hal
