#include "hal/interlocked_hal.hpp"

#include <stdexcept>

namespace pvcgel::hal {

InterlockedHal::InterlockedHal(std::unique_ptr<Hal> inner, std::unique_ptr<GpioLines> lines, int trip_after_timeouts)
    : inner_(std::move(inner)), lines_(std::move(lines)), trip_after_timeouts_(trip_after_timeouts) {
  if (!inner_ || !lines_) throw std::invalid_argument("InterlockedHal: backend and lines are required");
  lines_->set_enable(false);
  name_ = std::string(inner_->name()) + "+gpio";
}

InterlockedHal::~InterlockedHal() {
  lines_->set_enable(false);
  inner_.reset();
}

void InterlockedHal::trip() noexcept {
  lines_->set_enable(false);  // first, whatever else fails
  line_flag_.store(false, std::memory_order_relaxed);
  if (!tripped_) trips_.fetch_add(1, std::memory_order_relaxed);
  tripped_ = true;
  tripped_flag_.store(true, std::memory_order_relaxed);
}

void InterlockedHal::check_inner(HalStatus s) noexcept {
  consecutive_timeouts_ = s == HalStatus::timeout ? consecutive_timeouts_ + 1 : 0;
  // Faults after which the loop cannot be sure to ramp the amplifier down itself.
  if (s == HalStatus::disconnected || s == HalStatus::invalid_reply || s == HalStatus::device_fault ||
      consecutive_timeouts_ >= trip_after_timeouts_)
    trip();
}

HalStatus InterlockedHal::read_displacement(double& y_um) noexcept {
  const InterlockInputs in = lines_->poll();
  if (!in.ok || in.edge_seen || in.estop_active || in.amp_fault_active) trip();
  const HalStatus s = inner_->read_displacement(y_um);
  check_inner(s);
  return s;
}

HalStatus InterlockedHal::write_voltage(double voltage_V) noexcept {
  const HalStatus s = inner_->write_voltage(voltage_V);
  if (s != HalStatus::timeout) check_inner(s);
  if (tripped_ && s == HalStatus::ok) return HalStatus::device_fault;
  return s;
}

HalStatus InterlockedHal::set_high_voltage(bool enabled) noexcept {
  if (!enabled) {
    lines_->set_enable(false);
    line_flag_.store(false, std::memory_order_relaxed);
    enabled_ = false;
    return inner_->set_high_voltage(false);
  }
  enabled_ = true;
  const InterlockInputs in = lines_->poll();
  if (!in.ok || in.estop_active || in.amp_fault_active) {
    trip();  // refuse: an input is still active
    return HalStatus::device_fault;
  }
  tripped_ = false;
  tripped_flag_.store(false, std::memory_order_relaxed);
  consecutive_timeouts_ = 0;
  const HalStatus s = inner_->set_high_voltage(true);
  if (s != HalStatus::ok) {
    trip();
    return s;
  }
  if (!lines_->set_enable(true)) {
    trip();
    return HalStatus::device_fault;
  }
  line_flag_.store(true, std::memory_order_relaxed);
  return HalStatus::ok;
}

HalHealth InterlockedHal::health() const noexcept {
  HalHealth h = inner_->health();
  h.device_faults += trips_.load(std::memory_order_relaxed);
  h.high_voltage_enabled = line_flag_.load(std::memory_order_relaxed);
  h.amplifier_fault = h.amplifier_fault || tripped_flag_.load(std::memory_order_relaxed);
  return h;
}

}  // namespace pvcgel::hal
