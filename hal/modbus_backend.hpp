#pragma once
/// @file
/// The `modbus` HAL backend: the displacement sensor and the high-voltage
/// amplifier behind a Modbus TCP or RTU analog I/O module (libmodbus).

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "control/enum_table.hpp"
#include "hal/hal.hpp"
#include "hal/register_map.hpp"

struct _modbus;  // libmodbus' modbus_t

namespace pvcgel::hal {

/// Link and register map of a Modbus I/O module, validated by the config parser.
struct ModbusConfig {
  /// Physical link.
  enum class Transport : std::uint8_t { tcp, rtu };
  static constexpr auto kTransportNames = enum_table<Transport::tcp, Transport::rtu>({"tcp", "rtu"});
  friend constexpr const auto& names_of(Transport) noexcept { return kTransportNames; }
  Transport transport = Transport::tcp;
  std::string host = "127.0.0.1";  ///< TCP: address or host name of the module
  int port = 502;                  ///< TCP port
  std::string device;              ///< RTU: serial device, e.g. /dev/ttyUSB0
  int baud = 115200;               ///< RTU line settings
  char parity = 'N';               ///< 'N', 'E' or 'O'
  int data_bits = 8;
  int stop_bits = 1;
  int unit_id = 1;                 ///< Modbus unit (slave) id of the module

  double period_s = 1e-3;          ///< the loop period the link must keep up with
  int io_budget_us = 500;          ///< time allowed per cycle for read + write
  int response_timeout_us = 250;   ///< per transaction; 2 x this must fit io_budget_us
  int startup_probe_cycles = 200;  ///< cycles timed at start-up to measure the round trip
  int reconnect_after_failures = 10;  ///< consecutive failed transactions before the link is reset
  double reconnect_min_s = 0.05;   ///< reconnection back-off: first wait
  double reconnect_max_s = 2.0;    ///< reconnection back-off: longest wait

  bool sensor_in_holding = false;  ///< sensor and monitors in holding (FC 3) instead of input registers (FC 4)
  InputChannel sensor{0, {32, true, WordOrder::high_first}, {0.001, 0.0}};  ///< counts -> um
  AmplifierChannel amplifier;      ///< output volts -> holding register counts
  std::optional<InputChannel> monitor_voltage;  ///< counts -> amplifier output V, checked against the command
  double monitor_voltage_tolerance_V = 20.0;
  std::optional<InputChannel> monitor_current;  ///< counts -> amplifier output mA, checked against the limit
  double monitor_current_max_mA = 1.0;
  int monitor_fault_after_cycles = 3;  ///< consecutive voltage mismatches before an amplifier fault
};

/// Largest span of registers the sensor and monitors may occupy (one read per cycle).
inline constexpr int kMaxInputBlock = 16;

/// Round-trip measurement taken at start-up: one cycle = read block + write amplifier.
struct ModbusRtt {
  double p50_us = 0.0, p99_us = 0.0, max_us = 0.0;
  int cycles = 0;
  int timeouts = 0, garbled = 0;  ///< cycles that missed their deadline or got a malformed reply
};

/// Counters beyond HalHealth.
struct ModbusCounters {
  std::uint64_t timeouts = 0, exceptions = 0, garbage_frames = 0, disconnects = 0, reconnects = 0;
  std::uint64_t late_replies = 0;  ///< answers to an earlier, timed-out request (counted as timeouts too)
};

/// Modbus backend. The real-time calls touch the libmodbus context only while
/// the link is up; a broken link is handed (release/acquire on one atomic) to a
/// supervisor thread that reconnects with back-off, writes 0 V to the amplifier
/// register first, then hands it back. While it is down the RT calls return
/// HalStatus::disconnected at once. With high voltage disabled the amplifier
/// register is held at 0 V whatever is commanded.
class ModbusBackend final : public Hal {
 public:
  /// Connects, writes 0 V, measures the round trip and starts the supervisor.
  /// @throws control::ConfigError when the link cannot keep the configured rate
  ///   or the module rejects the map (names the key to change);
  ///   std::runtime_error when the module cannot be reached.
  explicit ModbusBackend(const ModbusConfig& config);
  /// Stops the supervisor and leaves the amplifier register at 0 V.
  ~ModbusBackend() override;
  ModbusBackend(ModbusBackend&&) = delete;

  HalStatus read_displacement(double& y_um) noexcept override;
  HalStatus write_voltage(double voltage_V) noexcept override;
  HalStatus set_high_voltage(bool enabled) noexcept override;
  [[nodiscard]] HalHealth health() const noexcept override;
  [[nodiscard]] std::string_view name() const noexcept override { return "modbus"; }

  /// Start-up round-trip measurement.
  [[nodiscard]] const ModbusRtt& startup_rtt() const noexcept { return rtt_; }
  /// Counters (any thread).
  [[nodiscard]] ModbusCounters counters() const noexcept;
  /// True while the RT thread owns a working link (any thread).
  [[nodiscard]] bool link_up() const noexcept { return link_.load(std::memory_order_acquire) == Link::up; }
  /// "tcp 127.0.0.1:502 unit 1" or "rtu /dev/ttyUSB0 115200 8N1 unit 1".
  [[nodiscard]] std::string describe_link() const;

 private:
  enum class Link : std::uint8_t { up, down };
  struct ContextDeleter {
    void operator()(_modbus* ctx) const noexcept;
  };

  static constexpr std::uint32_t kFirstContactTimeout_s = 1;  ///< first write after (re)connecting

  /// Counts a failed transaction in `consecutive_failures` (reads and writes
  /// separately) and hands the link to the supervisor at the threshold.
  HalStatus transaction_failed(int rc, int& consecutive_failures) noexcept;
  // Construction, in order (configuration time: these throw).
  void plan_input_block();
  void open_link();
  void check_first_contact();
  void set_cycle_timeout() noexcept;
  void flush_if_pending() noexcept;
  int read_block() noexcept;
  int write_counts(std::int64_t counts) noexcept;
  int write_zero() noexcept;
  void check_monitors() noexcept;
  void measure_round_trip();
  void supervise();

  ModbusConfig config_;
  std::unique_ptr<_modbus, ContextDeleter> ctx_;
  std::uint16_t block_start_ = 0;
  int block_count_ = 0;
  std::uint16_t block_[kMaxInputBlock] = {};
  std::int64_t zero_counts_ = 0;
  ModbusRtt rtt_;

  // RT-thread state.
  bool hv_enabled_ = false;
  double last_output_V_ = 0.0;
  int read_failures_ = 0, write_failures_ = 0;  // failed transactions in a row, per direction
  bool flush_pending_ = false;  // a timed-out or garbled reply may still be on its way
  // A request went unanswered since the last matched reply. Replies come in order, so a
  // frame that answers another request is that late answer while this holds, and garbage
  // once a matched reply has shown that nothing older is still on its way.
  bool reply_outstanding_ = false;
  int monitor_mismatches_ = 0;
  bool amplifier_fault_ = false;

  std::atomic<Link> link_{Link::down};
  std::atomic<std::uint64_t> reads_{0}, writes_{0}, timeouts_{0}, exceptions_{0}, garbage_{0}, device_faults_{0},
      disconnects_{0}, reconnects_{0}, late_replies_{0};
  std::atomic<bool> hv_flag_{false}, amp_fault_flag_{false};

  std::mutex supervisor_mutex_;  // supervisor thread and destructor only
  std::condition_variable supervisor_wake_;
  bool stopping_ = false;
  std::thread supervisor_;
};

}  // namespace pvcgel::hal
