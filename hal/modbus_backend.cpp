#include "hal/modbus_backend.hpp"

#include <modbus/modbus.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "control/config_error.hpp"

namespace pvcgel::hal {

using control::ConfigError;

namespace {

bool is_exception(int e) noexcept { return e >= EMBXILFUN && e <= EMBXGTAR; }
bool is_garbage(int e) noexcept { return e >= EMBBADCRC && e <= EMBBADSLAVE; }

std::string modbus_error(int e) { return modbus_strerror(e); }

/// Shortest time one cycle can take on a serial line: four frames (request and
/// reply of a read and a write), each followed by the 3.5-character silence.
double rtu_cycle_floor_us(const ModbusConfig& c, int read_registers, int write_registers) {
  const int bits_per_char = 1 + c.data_bits + (c.parity == 'N' ? 0 : 1) + c.stop_bits;
  const int read_req = 8, read_rsp = 5 + 2 * read_registers;
  const int write_req = write_registers == 1 ? 8 : 9 + 2 * write_registers, write_rsp = 8;
  const double chars = read_req + read_rsp + write_req + write_rsp + 4 * 3.5;
  return chars * bits_per_char / c.baud * 1e6;
}

}  // namespace

void ModbusBackend::ContextDeleter::operator()(_modbus* ctx) const noexcept {
  modbus_close(ctx);
  modbus_free(ctx);
}

ModbusBackend::ModbusBackend(const ModbusConfig& config) : config_(config) {
  plan_input_block();
  std::int64_t zero = 0;
  config_.amplifier.output_to_counts(0.0, zero);
  zero_counts_ = zero;
  open_link();
  check_first_contact();
  set_cycle_timeout();
  measure_round_trip();
  link_.store(Link::up, std::memory_order_release);
  supervisor_ = std::thread([this] { supervise(); });
}

void ModbusBackend::plan_input_block() {
  const auto& c = config_;
  // The block read each cycle: the sensor and any monitors.
  int lo = c.sensor.address, hi = c.sensor.address + c.sensor.format.register_count();
  for (const auto* m : {&c.monitor_voltage, &c.monitor_current}) {
    if (!*m) continue;
    lo = std::min<int>(lo, (*m)->address);
    hi = std::max<int>(hi, (*m)->address + (*m)->format.register_count());
  }
  if (hi - lo > kMaxInputBlock)
    throw ConfigError("hal.modbus.monitor_voltage.address",
                      "the sensor and monitor registers span " + std::to_string(hi - lo) +
                          " registers; they must lie within " + std::to_string(kMaxInputBlock) +
                          " so one transaction reads them all each cycle");
  block_start_ = static_cast<std::uint16_t>(lo);
  block_count_ = hi - lo;
}

void ModbusBackend::open_link() {
  const auto& c = config_;
  if (c.transport == ModbusConfig::Transport::rtu) {
    const double floor_us = rtu_cycle_floor_us(c, block_count_, c.amplifier.format.register_count());
    if (floor_us > c.io_budget_us) {
      std::ostringstream os;
      os << "at " << c.baud << " baud one cycle (read " << block_count_ << " registers + write the amplifier) takes at least "
         << std::lround(floor_us) << " us on the wire, more than the I/O budget of " << c.io_budget_us
         << " us (period " << std::lround(c.period_s * 1e6) << " us); raise the baud rate (module and hal.modbus.baud) "
         << "or lower the loop rate ([controller] period_s) and raise hal.modbus.io_budget_us";
      throw ConfigError("hal.modbus.baud", os.str());
    }
    ctx_.reset(modbus_new_rtu(c.device.c_str(), c.baud, c.parity, c.data_bits, c.stop_bits));
  } else {
    ctx_.reset(modbus_new_tcp_pi(c.host.c_str(), std::to_string(c.port).c_str()));
  }
  if (!ctx_) throw ConfigError("hal.modbus", "libmodbus refused the link settings: " + modbus_error(errno));
  if (modbus_set_slave(ctx_.get(), c.unit_id) != 0)
    throw ConfigError("hal.modbus.unit_id", "invalid unit id " + std::to_string(c.unit_id));
  // One deadline for the whole reply (byte timeout 0 = not used); generous for the first contact.
  modbus_set_byte_timeout(ctx_.get(), 0, 0);
  modbus_set_response_timeout(ctx_.get(), kFirstContactTimeout_s, 0);
  if (modbus_connect(ctx_.get()) != 0)
    throw std::runtime_error("Modbus: cannot connect to " + describe_link() + ": " + modbus_error(errno));
}

// The amplifier goes to 0 V before anything else; the first answers also tell
// whether unit id and addresses are right, so their errors name those keys.
void ModbusBackend::check_first_contact() {
  const auto& c = config_;
  if (write_zero() < 0) {
    const int e = errno;
    if (e == ETIMEDOUT)
      throw ConfigError("hal.modbus.unit_id", "no answer from " + describe_link() + " within " +
                                                  std::to_string(c.response_timeout_us) +
                                                  " us to the first write; check the unit id, wiring and line settings");
    if (e == EMBXGPATH || e == EMBXGTAR)
      throw ConfigError("hal.modbus.unit_id", describe_link() + " answered '" + modbus_error(e) +
                                                  "': no device with this unit id behind it");
    if (e == EMBXILADD || e == EMBXILFUN || e == EMBXILVAL)
      throw ConfigError("hal.modbus.amplifier.address",
                        "writing holding register " + std::to_string(c.amplifier.address) + " failed: '" +
                            modbus_error(e) + "'");
    throw std::runtime_error("Modbus: writing 0 V to " + describe_link() + " failed: " + modbus_error(e));
  }
  if (read_block() != block_count_) {
    const int e = errno;
    if (is_exception(e))
      throw ConfigError("hal.modbus.sensor.address",
                        std::string("reading ") + (c.sensor_in_holding ? "holding" : "input") + " registers " +
                            std::to_string(block_start_) + ".." + std::to_string(block_start_ + block_count_ - 1) +
                            " failed: '" + modbus_error(e) + "'");
    throw std::runtime_error("Modbus: reading the sensor from " + describe_link() + " failed: " + modbus_error(e));
  }
}

ModbusBackend::~ModbusBackend() {
  {
    std::lock_guard lock(supervisor_mutex_);
    stopping_ = true;
  }
  supervisor_wake_.notify_all();
  if (supervisor_.joinable()) supervisor_.join();
  if (link_.load(std::memory_order_acquire) == Link::up) write_zero();
}

std::string ModbusBackend::describe_link() const {
  const auto& c = config_;
  std::ostringstream os;
  if (c.transport == ModbusConfig::Transport::tcp)
    os << "tcp " << c.host << ":" << c.port;
  else
    os << "rtu " << c.device << " " << c.baud << " " << c.data_bits << c.parity << c.stop_bits;
  os << " unit " << c.unit_id;
  return os.str();
}

void ModbusBackend::set_cycle_timeout() noexcept {
  modbus_set_response_timeout(ctx_.get(), static_cast<std::uint32_t>(config_.response_timeout_us / 1000000),
                              static_cast<std::uint32_t>(config_.response_timeout_us % 1000000));
}

void ModbusBackend::flush_if_pending() noexcept {
  // A reply that came after its deadline would otherwise answer this request.
  if (!flush_pending_) return;
  modbus_flush(ctx_.get());
  flush_pending_ = false;
}

int ModbusBackend::read_block() noexcept {
  return config_.sensor_in_holding ? modbus_read_registers(ctx_.get(), block_start_, block_count_, block_)
                                   : modbus_read_input_registers(ctx_.get(), block_start_, block_count_, block_);
}

int ModbusBackend::write_counts(std::int64_t counts) noexcept {
  std::uint16_t regs[2] = {};
  if (!encode_counts(counts, config_.amplifier.format, regs)) {
    errno = EINVAL;
    return -1;
  }
  if (config_.amplifier.format.register_count() == 1) return modbus_write_register(ctx_.get(), config_.amplifier.address, regs[0]);
  return modbus_write_registers(ctx_.get(), config_.amplifier.address, 2, regs) == 2 ? 1 : -1;
}

int ModbusBackend::write_zero() noexcept { return write_counts(zero_counts_); }

void ModbusBackend::measure_round_trip() {
  std::vector<double> us;
  us.reserve(static_cast<size_t>(config_.startup_probe_cycles));
  const int warm_up = 10;  // first requests of a fresh connection are slow on some servers
  for (int i = -warm_up; i < config_.startup_probe_cycles; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const int rc_read = read_block();
    const int e_read = errno;
    const int rc_write = rc_read == block_count_ ? write_zero() : 0;
    const auto t1 = std::chrono::steady_clock::now();
    if (rc_read != block_count_ || rc_write < 0) {
      const int e = rc_read != block_count_ ? e_read : errno;
      if (e == ETIMEDOUT || is_garbage(e)) {
        // Over budget by definition; let the late reply arrive, then drop it.
        if (i >= 0) {
          us.push_back(1e9);
          ++(e == ETIMEDOUT ? rtt_.timeouts : rtt_.garbled);
        }
        std::this_thread::sleep_for(std::chrono::microseconds(4 * config_.response_timeout_us));
        modbus_flush(ctx_.get());
        continue;
      }
      throw std::runtime_error("Modbus: round-trip measurement against " + describe_link() + " failed at cycle " +
                               std::to_string(i) + ": " + modbus_error(e));
    }
    if (i >= 0) us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
  }
  std::sort(us.begin(), us.end());
  const auto q = [&](double p) { return us[static_cast<size_t>(p * static_cast<double>(us.size() - 1))]; };
  rtt_.p50_us = q(0.5);
  rtt_.p99_us = q(0.99);
  rtt_.max_us = us.back();
  rtt_.cycles = static_cast<int>(us.size());
  if (rtt_.p99_us > config_.io_budget_us) {
    std::ostringstream os;
    os.precision(0);
    os << std::fixed << "the link " << describe_link() << " cannot keep the rate: one cycle (read " << block_count_
       << " registers + write the amplifier) measured p50 " << rtt_.p50_us << " us, p99 "
       << (rtt_.p99_us >= 1e9 ? std::string("timeout") : std::to_string(std::lround(rtt_.p99_us)) + " us")
       << " over " << rtt_.cycles << " cycles (" << rtt_.timeouts << " timed out, " << rtt_.garbled
       << " garbled), budget " << config_.io_budget_us << " us of a "
       << config_.period_s * 1e6 << " us period; lower the loop rate ([controller] period_s) and raise "
       << "hal.modbus.io_budget_us and response_timeout_us, or use a faster link"
       << (config_.transport == ModbusConfig::Transport::rtu ? " (higher baud rate)" : "");
    throw ConfigError("hal.modbus.io_budget_us", os.str());
  }
}

HalStatus ModbusBackend::transaction_failed(int rc, int& consecutive_failures) noexcept {
  const int e = rc < 0 ? errno : EMBMDATA;
  HalStatus status = HalStatus::invalid_reply;
  bool reset_link = false;
  if (e == ETIMEDOUT) {
    timeouts_.fetch_add(1, std::memory_order_relaxed);
    status = HalStatus::timeout;
    flush_pending_ = true;
    reply_outstanding_ = true;
  } else if (e == EMBBADDATA && reply_outstanding_) {
    // The late answer to a request that timed out (this request's own answer is
    // now the one outstanding): one more missed sample, not a broken device.
    late_replies_.fetch_add(1, std::memory_order_relaxed);
    timeouts_.fetch_add(1, std::memory_order_relaxed);
    status = HalStatus::timeout;
    modbus_flush(ctx_.get());
    flush_pending_ = true;
  } else if (is_exception(e)) {
    exceptions_.fetch_add(1, std::memory_order_relaxed);
  } else if (is_garbage(e) || rc >= 0) {
    garbage_.fetch_add(1, std::memory_order_relaxed);
    modbus_flush(ctx_.get());
    flush_pending_ = true;
  } else {
    reset_link = true;  // socket or device error: the link is gone
  }
  if (reset_link || ++consecutive_failures >= config_.reconnect_after_failures) {
    read_failures_ = write_failures_ = 0;
    // A lost link counts as an interlock trip: whatever the loop still commands
    // (a ramp-down), after reconnecting the register stays at 0 V until re-armed.
    hv_enabled_ = false;
    hv_flag_.store(false, std::memory_order_relaxed);
    disconnects_.fetch_add(1, std::memory_order_relaxed);
    link_.store(Link::down, std::memory_order_release);  // from here on the supervisor owns the context
    return HalStatus::disconnected;
  }
  return status;
}

HalStatus ModbusBackend::read_displacement(double& y_um) noexcept {
  reads_.fetch_add(1, std::memory_order_relaxed);
  if (link_.load(std::memory_order_acquire) != Link::up) return HalStatus::disconnected;
  flush_if_pending();
  const int rc = read_block();
  if (rc != block_count_) return transaction_failed(rc, read_failures_);
  reply_outstanding_ = false;
  read_failures_ = 0;  // reads only: a module that answers reads but fails writes must still reach the threshold
  y_um = config_.sensor.decode(block_, block_start_);
  check_monitors();
  return HalStatus::ok;
}

void ModbusBackend::check_monitors() noexcept {
  const auto& c = config_;
  bool fault = false;
  if (c.monitor_voltage) {
    const double measured_V = c.monitor_voltage->decode(block_, block_start_);
    // Compared with the command of the previous cycle: the one the amplifier has had time to follow.
    monitor_mismatches_ = std::abs(measured_V - last_output_V_) > c.monitor_voltage_tolerance_V ? monitor_mismatches_ + 1 : 0;
    fault = monitor_mismatches_ >= c.monitor_fault_after_cycles;
  }
  if (c.monitor_current && std::abs(c.monitor_current->decode(block_, block_start_)) > c.monitor_current_max_mA)
    fault = true;
  if (fault && !amplifier_fault_) {
    amplifier_fault_ = true;
    amp_fault_flag_.store(true, std::memory_order_relaxed);
  }
}

HalStatus ModbusBackend::write_voltage(double voltage_V) noexcept {
  writes_.fetch_add(1, std::memory_order_relaxed);
  if (link_.load(std::memory_order_acquire) != Link::up) return HalStatus::disconnected;
  std::int64_t counts = zero_counts_;
  if (hv_enabled_) config_.amplifier.output_to_counts(voltage_V, counts);
  flush_if_pending();
  const int rc = write_counts(counts);
  if (rc != 1) return transaction_failed(rc < 0 ? rc : 0, write_failures_);
  write_failures_ = 0;
  reply_outstanding_ = false;
  last_output_V_ = config_.amplifier.counts_to_output(counts);
  if (amplifier_fault_) {
    device_faults_.fetch_add(1, std::memory_order_relaxed);
    return HalStatus::device_fault;
  }
  return HalStatus::ok;
}

HalStatus ModbusBackend::set_high_voltage(bool enabled) noexcept {
  const bool up = link_.load(std::memory_order_acquire) == Link::up;
  if (enabled && !up) return HalStatus::disconnected;  // stays disabled: nothing to arm
  hv_enabled_ = enabled;
  hv_flag_.store(enabled, std::memory_order_relaxed);
  if (enabled) {
    // Re-arming clears a latched monitor fault; it comes back if the mismatch persists.
    amplifier_fault_ = false;
    monitor_mismatches_ = 0;
    amp_fault_flag_.store(false, std::memory_order_relaxed);
    return HalStatus::ok;
  }
  // Without an enable line of its own the backend disables by commanding 0 V now.
  if (up) {
    flush_if_pending();
    const int rc = write_zero();
    if (rc != 1) return transaction_failed(rc < 0 ? rc : 0, write_failures_);
    reply_outstanding_ = false;
    last_output_V_ = 0.0;
  }
  return HalStatus::ok;
}

HalHealth ModbusBackend::health() const noexcept {
  HalHealth h;
  h.reads = reads_.load(std::memory_order_relaxed);
  h.writes = writes_.load(std::memory_order_relaxed);
  h.timeouts = timeouts_.load(std::memory_order_relaxed);
  h.exceptions = exceptions_.load(std::memory_order_relaxed);
  h.garbage_frames = garbage_.load(std::memory_order_relaxed);
  h.invalid_replies = h.exceptions + h.garbage_frames;
  h.device_faults = device_faults_.load(std::memory_order_relaxed);
  h.reconnects = reconnects_.load(std::memory_order_relaxed);
  h.link_up = link_up();
  h.high_voltage_enabled = hv_flag_.load(std::memory_order_relaxed);
  h.amplifier_fault = amp_fault_flag_.load(std::memory_order_relaxed);
  return h;
}

ModbusCounters ModbusBackend::counters() const noexcept {
  return {timeouts_.load(std::memory_order_relaxed),     exceptions_.load(std::memory_order_relaxed),
          garbage_.load(std::memory_order_relaxed),      disconnects_.load(std::memory_order_relaxed),
          reconnects_.load(std::memory_order_relaxed),   late_replies_.load(std::memory_order_relaxed)};
}

void ModbusBackend::supervise() {
  using namespace std::chrono;
  const auto min_wait = duration<double>(config_.reconnect_min_s), max_wait = duration<double>(config_.reconnect_max_s);
  auto wait = min_wait;
  std::unique_lock lock(supervisor_mutex_);
  while (!stopping_) {
    if (link_.load(std::memory_order_acquire) == Link::up) {
      // The RT thread owns the context; look again soon.
      supervisor_wake_.wait_for(lock, milliseconds(5));
      continue;
    }
    // The RT thread has let go of the context: it is ours until we store `up`.
    modbus_close(ctx_.get());
    supervisor_wake_.wait_for(lock, wait, [this] { return stopping_; });
    if (stopping_) break;
    modbus_set_response_timeout(ctx_.get(), kFirstContactTimeout_s, 0);
    const bool zero_written = modbus_connect(ctx_.get()) == 0 && write_zero() == 1;
    set_cycle_timeout();
    if (zero_written) {
      flush_pending_ = reply_outstanding_ = false;  // a new connection: nothing of the old one can arrive
      read_failures_ = write_failures_ = 0;
      wait = min_wait;
      reconnects_.fetch_add(1, std::memory_order_relaxed);
      link_.store(Link::up, std::memory_order_release);
    } else {
      modbus_close(ctx_.get());
      wait = std::min(max_wait, wait * 2);
    }
  }
}

}  // namespace pvcgel::hal
