#include "daemon/trajectory.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>

#include "control/config_error.hpp"

namespace pvcgel::daemon {

using control::ConfigError;

namespace {
std::vector<double> parse_numbers(std::string_view s, const std::string& spec) {
  std::vector<double> out;
  std::stringstream ss{std::string(s)};
  std::string item;
  while (std::getline(ss, item, ',')) {
    double v = 0.0;
    const auto* b = item.data();
    const auto [p, ec] = std::from_chars(b, b + item.size(), v);
    if (ec != std::errc() || p != b + item.size() || !std::isfinite(v))
      throw ConfigError("trajectory", "'" + spec + "': '" + item + "' is not a number");
    out.push_back(v);
  }
  return out;
}
}  // namespace

Trajectory Trajectory::parse(std::string_view spec_view) {
  Trajectory t;
  t.spec_ = std::string(spec_view);
  const std::string& spec = t.spec_;
  if (auto paper = control::paper_reference(spec); paper && spec.rfind("paper-", 0) == 0) {
    t.analytic_ = *paper;
    return t;
  }
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string args = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (kind == "hold" || kind == "sine" || kind == "multisine") {
    t.parse_analytic(kind, args);
    return t;
  }
  if (kind == "csv") {
    t.read_csv(args);
    return t;
  }
  throw ConfigError("trajectory", "unknown trajectory '" + spec +
                                      "' (hold:, sine:, multisine:, csv:, paper-0.1hz, paper-0.5hz, "
                                      "paper-1hz, paper-multi)");
}

void Trajectory::parse_analytic(const std::string& kind, const std::string& args) {
  const auto v = parse_numbers(args, spec_);
  auto& a = analytic_;
  if (kind == "hold" && v.size() == 1) {
    a.offset_um = v[0];
    return;
  }
  if (kind == "sine" && v.size() == 3) {
    a.offset_um = v[0];
    a.tones[0] = {v[1], v[2], 0.0};
    a.n_tones = 1;
  } else if (kind == "multisine" && v.size() >= 3 && v.size() % 2 == 1 &&
             (v.size() - 1) / 2 <= static_cast<size_t>(control::MultiSine::kMaxTones)) {
    a.offset_um = v[0];
    a.n_tones = static_cast<int>((v.size() - 1) / 2);
    for (int i = 0; i < a.n_tones; ++i)
      a.tones[static_cast<size_t>(i)] = {v[static_cast<size_t>(1 + 2 * i)], v[static_cast<size_t>(2 + 2 * i)], 0.0};
  } else {
    throw ConfigError("trajectory", "'" + spec_ +
                                        "': expected hold:R, sine:OFFSET,AMPLITUDE,FREQ_HZ or "
                                        "multisine:OFFSET,A1,F1[,A2,F2...] (at most 8 tones)");
  }
  for (int i = 0; i < a.n_tones; ++i)
    if (!(a.tones[static_cast<size_t>(i)].frequency_Hz > 0.0))
      throw ConfigError("trajectory", "'" + spec_ + "': frequencies must be positive");
}

void Trajectory::read_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError("trajectory", "cannot open CSV file '" + path + "'");
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    if (line.rfind("t_s", 0) == 0) continue;  // header
    const auto where = path + ":" + std::to_string(lineno) + ": ";
    std::vector<double> v;
    try {
      v = parse_numbers(line, spec_);
    } catch (const ConfigError&) {
      throw ConfigError("trajectory", where + "expected 't_s,r_um', got '" + line + "'");
    }
    if (v.size() != 2) throw ConfigError("trajectory", where + "expected 2 columns t_s,r_um");
    if (!t_.empty() && !(v[0] > t_.back())) throw ConfigError("trajectory", where + "time must increase strictly");
    t_.push_back(v[0]);
    r_.push_back(v[1]);
    line_.push_back(lineno);
  }
  if (t_.size() < 2) throw ConfigError("trajectory", path + ": needs at least 2 samples");
  if (t_.front() != 0.0) throw ConfigError("trajectory", path + ": the first sample must be at t_s = 0");
  end_s_ = t_.back();
}

void Trajectory::check_limits(const SetpointLimits& l) const {
  char buf[200];
  const auto refuse = [&](const std::string& where, const char* what, double value, double limit) {
    std::snprintf(buf, sizeof buf, "%s %.6g is beyond the [setpoints] limit %.6g", what, value, limit);
    throw ConfigError("trajectory", where + buf);
  };
  if (t_.empty()) {
    double amplitude = 0.0, slope = 0.0;
    for (int i = 0; i < analytic_.n_tones; ++i) {
      const auto& tone = analytic_.tones[static_cast<size_t>(i)];
      amplitude += std::abs(tone.amplitude_um);
      slope += 2.0 * std::numbers::pi * tone.frequency_Hz * std::abs(tone.amplitude_um);
    }
    if (analytic_.offset_um + amplitude > l.max_um) refuse("'" + spec_ + "': ", "maximum (um)", analytic_.offset_um + amplitude, l.max_um);
    if (analytic_.offset_um - amplitude < l.min_um) refuse("'" + spec_ + "': ", "minimum (um)", analytic_.offset_um - amplitude, l.min_um);
    if (slope > l.max_slope_um_per_s) refuse("'" + spec_ + "': ", "peak slope (um/s)", slope, l.max_slope_um_per_s);
    return;
  }
  const std::string file = spec_.substr(spec_.find(':') + 1);
  for (size_t i = 0; i < t_.size(); ++i) {
    const std::string where = file + ":" + std::to_string(line_[i]) + ": ";
    if (r_[i] > l.max_um) refuse(where, "r_um", r_[i], l.max_um);
    if (r_[i] < l.min_um) refuse(where, "r_um", r_[i], l.min_um);
    if (i == 0) continue;
    const double step = std::abs(r_[i] - r_[i - 1]);
    if (step > l.max_step_um) refuse(where, "step from the sample before (um)", step, l.max_step_um);
    if (step / (t_[i] - t_[i - 1]) > l.max_slope_um_per_s)
      refuse(where, "slope (um/s)", step / (t_[i] - t_[i - 1]), l.max_slope_um_per_s);
  }
}

double Trajectory::at(double time) const noexcept {
  if (t_.empty()) return analytic_(time);
  if (time <= t_.front()) return r_.front();
  if (time >= t_.back()) return r_.back();
  const auto it = std::upper_bound(t_.begin(), t_.end(), time);
  const size_t i = static_cast<size_t>(it - t_.begin());
  const double s = (time - t_[i - 1]) / (t_[i] - t_[i - 1]);
  return r_[i - 1] + s * (r_[i] - r_[i - 1]);
}

}  // namespace pvcgel::daemon
