#include "hal/sim_backend.hpp"

#include <cmath>
#include <limits>

namespace pvcgel::hal {

SimBackend::SimBackend(const control::SimRigConfig& config) : rig_(config) { rig_.reset_steady_state(0.0); }

HalStatus SimBackend::read_displacement(double& y) noexcept {
  reads_.fetch_add(1, std::memory_order_relaxed);
  if (scheduled_at_samples_ >= 0 && samples_ >= scheduled_at_samples_) {
    fault_.store(scheduled_fault_, std::memory_order_relaxed);
    scheduled_at_samples_ = -1;
  }
  switch (fault_.load(std::memory_order_relaxed)) {
    case SimFault::sensor_nan:
      y = std::numeric_limits<double>::quiet_NaN();
      return HalStatus::ok;  // the device "answered"; validation is the loop's job
    case SimFault::sensor_stuck:
      y = last_reading_;
      return HalStatus::ok;
    case SimFault::sensor_out_of_range:
      y = 1e6;
      return HalStatus::ok;
    case SimFault::sensor_dropout:
      timeouts_.fetch_add(1, std::memory_order_relaxed);
      return HalStatus::timeout;
    default:
      break;
  }
  y = last_reading_ = rig_.measure();
  return HalStatus::ok;
}

HalStatus SimBackend::write_voltage(double v) noexcept {
  writes_.fetch_add(1, std::memory_order_relaxed);
  const SimFault fault = fault_.load(std::memory_order_relaxed);
  const bool amp_fault = fault == SimFault::amplifier_fault;
  const bool write_lost = fault == SimFault::write_failed || fault == SimFault::write_timeout;
  amp_fault_flag_.store(amp_fault, std::memory_order_relaxed);
  // A lost write leaves the amplifier at its last command (as an analog output module does).
  if (!write_lost) applied_V_ = v;
  // A faulted or disabled amplifier outputs nothing; the plant still evolves.
  rig_.apply(hv_enabled_ && !amp_fault ? applied_V_ : 0.0);
  ++samples_;
  if (amp_fault) {
    device_faults_.fetch_add(1, std::memory_order_relaxed);
    return HalStatus::device_fault;
  }
  if (fault == SimFault::write_timeout) {
    timeouts_.fetch_add(1, std::memory_order_relaxed);
    return HalStatus::timeout;
  }
  if (fault == SimFault::write_failed) {
    invalid_.fetch_add(1, std::memory_order_relaxed);
    return HalStatus::invalid_reply;
  }
  return HalStatus::ok;
}

HalStatus SimBackend::set_high_voltage(bool enabled) noexcept {
  if (enabled && fault_.load(std::memory_order_relaxed) == SimFault::hv_enable_failed) {
    device_faults_.fetch_add(1, std::memory_order_relaxed);
    return HalStatus::device_fault;  // the enable did not take: high voltage stays off
  }
  hv_enabled_ = enabled;
  hv_flag_.store(enabled, std::memory_order_relaxed);
  return HalStatus::ok;
}

HalHealth SimBackend::health() const noexcept {
  HalHealth h;
  h.reads = reads_.load(std::memory_order_relaxed);
  h.writes = writes_.load(std::memory_order_relaxed);
  h.timeouts = timeouts_.load(std::memory_order_relaxed);
  h.invalid_replies = invalid_.load(std::memory_order_relaxed);
  h.device_faults = device_faults_.load(std::memory_order_relaxed);
  h.high_voltage_enabled = hv_flag_.load(std::memory_order_relaxed);
  h.amplifier_fault = amp_fault_flag_.load(std::memory_order_relaxed);
  return h;
}

}  // namespace pvcgel::hal
