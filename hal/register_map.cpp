#include "hal/register_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pvcgel::hal {

std::int64_t RegisterFormat::min_counts() const noexcept {
  if (!is_signed) return 0;
  return width_bits == 32 ? std::numeric_limits<std::int32_t>::min() : std::numeric_limits<std::int16_t>::min();
}

std::int64_t RegisterFormat::max_counts() const noexcept {
  if (width_bits == 32)
    return is_signed ? std::numeric_limits<std::int32_t>::max() : std::numeric_limits<std::uint32_t>::max();
  return is_signed ? std::numeric_limits<std::int16_t>::max() : std::numeric_limits<std::uint16_t>::max();
}

std::int64_t decode_counts(const std::uint16_t* regs, const RegisterFormat& f) noexcept {
  if (f.width_bits != 32) {
    return f.is_signed ? static_cast<std::int64_t>(static_cast<std::int16_t>(regs[0])) : regs[0];
  }
  const std::uint32_t hi = f.word_order == WordOrder::high_first ? regs[0] : regs[1];
  const std::uint32_t lo = f.word_order == WordOrder::high_first ? regs[1] : regs[0];
  const std::uint32_t raw = (hi << 16) | lo;
  return f.is_signed ? static_cast<std::int64_t>(static_cast<std::int32_t>(raw)) : raw;
}

bool encode_counts(std::int64_t counts, const RegisterFormat& f, std::uint16_t* regs) noexcept {
  if (counts < f.min_counts() || counts > f.max_counts()) return false;
  const auto raw = static_cast<std::uint32_t>(counts);  // two's complement for negative values
  if (f.width_bits != 32) {
    regs[0] = static_cast<std::uint16_t>(raw & 0xFFFFu);
    return true;
  }
  const auto hi = static_cast<std::uint16_t>(raw >> 16), lo = static_cast<std::uint16_t>(raw & 0xFFFFu);
  regs[0] = f.word_order == WordOrder::high_first ? hi : lo;
  regs[1] = f.word_order == WordOrder::high_first ? lo : hi;
  return true;
}

double LinearMap::to_counts(double physical) const noexcept { return std::nearbyint((physical - offset) / scale); }

bool AmplifierChannel::output_to_counts(double output_V, std::int64_t& counts) const noexcept {
  if (!std::isfinite(output_V)) {
    counts = static_cast<std::int64_t>(std::clamp(input_map.to_counts(0.0), static_cast<double>(format.min_counts()),
                                                  static_cast<double>(format.max_counts())));
    return false;
  }
  const double input_V = output_V / gain_V_per_V;
  const double ideal = input_map.to_counts(input_V);
  // Saturate to the module's range, in counts (the scale may be negative).
  const double a = input_map.to_counts(input_min_V), b = input_map.to_counts(input_max_V);
  double c = std::clamp(ideal, std::min(a, b), std::max(a, b));
  c = std::clamp(c, static_cast<double>(format.min_counts()), static_cast<double>(format.max_counts()));
  counts = static_cast<std::int64_t>(c);
  return std::abs(c - ideal) <= 1.0;
}

}  // namespace pvcgel::hal
