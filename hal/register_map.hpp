#pragma once
/// @file
/// Modbus register formats and the linear maps between register counts and
/// physical units. Pure computation: no I/O, no allocation, noexcept.

#include <cstdint>
#include <optional>
#include <string_view>

#include "control/enum_table.hpp"

namespace pvcgel::hal {

/// Order of the two 16-bit registers of a 32-bit value.
enum class WordOrder : std::uint8_t {
  high_first,  ///< register N holds bits 31..16 (Modbus "big-endian", most modules)
  low_first,   ///< register N holds bits 15..0 ("word-swapped")
};
inline constexpr auto kWordOrderNames = enum_table<WordOrder::high_first, WordOrder::low_first>({"high_first", "low_first"});
constexpr const auto& names_of(WordOrder) noexcept { return kWordOrderNames; }
constexpr std::string_view to_string(WordOrder w) noexcept { return kWordOrderNames.to_string(w); }

/// How an integer is laid out in one or two consecutive registers.
struct RegisterFormat {
  std::uint8_t width_bits = 16;  ///< 16 or 32
  bool is_signed = false;        ///< two's complement when true
  WordOrder word_order = WordOrder::high_first;

  /// Registers the value occupies (1 or 2).
  [[nodiscard]] constexpr int register_count() const noexcept { return width_bits == 32 ? 2 : 1; }
  /// Smallest representable count.
  [[nodiscard]] std::int64_t min_counts() const noexcept;
  /// Largest representable count.
  [[nodiscard]] std::int64_t max_counts() const noexcept;
};


/// The integer held by `regs[0..register_count)`.
std::int64_t decode_counts(const std::uint16_t* regs, const RegisterFormat& format) noexcept;

/// Writes `counts` into `regs[0..register_count)`. @return false (regs untouched)
/// when counts is outside [min_counts, max_counts].
bool encode_counts(std::int64_t counts, const RegisterFormat& format, std::uint16_t* regs) noexcept;

/// physical = offset + scale * counts.
struct LinearMap {
  double scale = 1.0;   ///< physical units per count (non-zero)
  double offset = 0.0;  ///< physical value at 0 counts

  /// Counts -> physical.
  [[nodiscard]] constexpr double to_physical(std::int64_t counts) const noexcept {
    return offset + scale * static_cast<double>(counts);
  }
  /// Physical -> counts, rounded to nearest (no range check).
  [[nodiscard]] double to_counts(double physical) const noexcept;
};

/// A register read as a physical quantity (sensor, monitors).
struct InputChannel {
  std::uint16_t address = 0;  ///< first register (zero-based protocol address)
  RegisterFormat format;
  LinearMap map;              ///< counts -> physical unit of the channel

  /// Physical value from the registers of a block read starting at `block_start`.
  [[nodiscard]] double decode(const std::uint16_t* block, std::uint16_t block_start) const noexcept {
    return map.to_physical(decode_counts(block + (address - block_start), format));
  }
};

/// The amplifier's analog control input, in a holding register. The amplifier
/// multiplies its input by a fixed gain: output_V = gain * input_V.
struct AmplifierChannel {
  std::uint16_t address = 0;   ///< holding register (zero-based protocol address)
  RegisterFormat format;
  double gain_V_per_V = 100.0;      ///< amplifier gain (output volts per input volt)
  LinearMap input_map{0.001, 0.0};  ///< module counts -> amplifier input volts
  double input_min_V = 0.0;         ///< module output range (amplifier input)
  double input_max_V = 10.0;

  /// Counts that make the amplifier output `output_V`, saturated to the module's
  /// range and the register format. @return false if the saturation changed the value
  /// by more than one count (the command cannot be represented).
  bool output_to_counts(double output_V, std::int64_t& counts) const noexcept;
  /// Amplifier output for a register value.
  [[nodiscard]] double counts_to_output(std::int64_t counts) const noexcept {
    return gain_V_per_V * input_map.to_physical(counts);
  }
};

}  // namespace pvcgel::hal
