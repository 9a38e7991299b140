#pragma once
/// @file
/// Analytic reference trajectories, including the paper's.

#include <array>
#include <cmath>
#include <numbers>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pvcgel::control {

/// `r(t) = offset + sum_i a_i sin(2 pi f_i t + phi_i)`, up to kMaxTones tones.
/// Covers hold (no tones), sines and the paper's multi-harmonic reference.
struct MultiSine {
  static constexpr int kMaxTones = 8;
  struct Tone {
    double amplitude_um = 0.0;
    double frequency_Hz = 0.0;
    double phase_rad = 0.0;
  };
  double offset_um = 0.0;
  std::array<Tone, kMaxTones> tones{};
  int n_tones = 0;

  /// r(t). Real-time safe.
  [[nodiscard]] double operator()(double t_s) const noexcept {
    double r = offset_um;
    for (int i = 0; i < n_tones; ++i) {
      const auto& k = tones[static_cast<size_t>(i)];
      r += k.amplitude_um * std::sin(2.0 * std::numbers::pi * k.frequency_Hz * t_s + k.phase_rad);
    }
    return r;
  }
  /// Longest period among the tones (0 for a hold).
  [[nodiscard]] double slowest_period_s() const noexcept {
    double p = 0.0;
    for (int i = 0; i < n_tones; ++i) p = std::max(p, 1.0 / tones[static_cast<size_t>(i)].frequency_Hz);
    return p;
  }
};

/// The paper's references (Section V-C), by the names the tools use:
/// "0.1Hz", "0.5Hz", "1Hz" (y_r1 = 100 + 25 sin(2 pi f t) um) and "multi" (y_r2).
/// Also accepts "paper-0.1hz", "paper-0.5hz", "paper-1hz", "paper-multi".
std::optional<MultiSine> paper_reference(std::string_view name);
/// The four canonical names in Table III's order.
inline const std::vector<std::string> kPaperReferenceNames{"0.1Hz", "0.5Hz", "1Hz", "multi"};

/// `m` as a multisine segment's values, [offset, a1, f1, phi1, a2, f2, phi2, ...] (the DDS trajectory layout;
/// with one tone also a sine segment's). Configuration time: it allocates.
std::vector<double> multisine_segment_values(const MultiSine& m);

}  // namespace pvcgel::control
