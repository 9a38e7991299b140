#include "control/reference_signal.hpp"

#include <algorithm>
#include <cctype>

namespace pvcgel::control {

std::optional<MultiSine> paper_reference(std::string_view name) {
  std::string n(name);
  std::transform(n.begin(), n.end(), n.begin(), [](unsigned char c) { return std::tolower(c); });
  if (n.rfind("paper-", 0) == 0) n = n.substr(6);
  MultiSine r;
  auto sine = [&](double f) {
    r.offset_um = 100.0;
    r.tones[0] = {25.0, f, 0.0};
    r.n_tones = 1;
    return r;
  };
  if (n == "0.1hz") return sine(0.1);
  if (n == "0.5hz") return sine(0.5);
  if (n == "1hz") return sine(1.0);
  if (n == "multi") {
    // y_ra + y_rb + y_rc = (33 + 5 sin(0.2 pi t)) + (33 + 7 sin(pi t)) + (30 + 12 sin(2 pi t))
    r.offset_um = 33.0 + 33.0 + 30.0;
    r.tones[0] = {5.0, 0.1, 0.0};
    r.tones[1] = {7.0, 0.5, 0.0};
    r.tones[2] = {12.0, 1.0, 0.0};
    r.n_tones = 3;
    return r;
  }
  return std::nullopt;
}

std::vector<double> multisine_segment_values(const MultiSine& m) {
  std::vector<double> values{m.offset_um};
  for (int i = 0; i < m.n_tones; ++i) {
    const auto& tone = m.tones[static_cast<size_t>(i)];
    values.insert(values.end(), {tone.amplitude_um, tone.frequency_Hz, tone.phase_rad});
  }
  return values;
}

}  // namespace pvcgel::control
