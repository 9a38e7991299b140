#include "control/identification/excitation_plan.hpp"

#include <cmath>
#include <numbers>
#include <sstream>

#include "control/config_error.hpp"

namespace pvcgel::control::identification {

double SinePoint::voltage_V(double t_s) const noexcept {
  return bias_V + amplitude_V * std::sin(2.0 * std::numbers::pi * frequency_Hz * t_s);
}

namespace {
std::string describe(const SinePoint& p) {
  std::ostringstream os;
  os << "point A = " << p.amplitude_V << " V, B = " << p.bias_V << " V, f = " << p.frequency_Hz << " Hz";
  return os.str();
}
}  // namespace

ExcitationPlan::ExcitationPlan(std::vector<SinePoint> points, double Ts, double vmin, double vmax)
    : points_(std::move(points)), sample_time_s_(Ts) {
  const std::string key = "ident.plan";
  if (!(Ts > 0.0)) throw ConfigError(key, "sample time must be positive");
  if (!(vmin >= 0.0 && vmax <= 1000.0 && vmax > vmin))
    throw ConfigError(key, "voltage limits must satisfy 0 <= min < max <= 1000 V");
  if (points_.empty()) throw ConfigError(key, "no experiments");
  for (const auto& p : points_) {
    std::ostringstream os;
    if (!(p.amplitude_V > 0.0 && std::isfinite(p.amplitude_V)))
      throw ConfigError(key, describe(p) + ": amplitude must be positive");
    if (!std::isfinite(p.bias_V) || p.bias_V - p.amplitude_V < vmin || p.bias_V + p.amplitude_V > vmax) {
      os << describe(p) << ": the sine spans " << p.bias_V - p.amplitude_V << " .. " << p.bias_V + p.amplitude_V
         << " V, outside " << vmin << " .. " << vmax << " V (need B - A >= " << vmin << " and B + A <= " << vmax
         << ")";
      throw ConfigError(key, os.str());
    }
    if (!(p.frequency_Hz > 0.0 && p.frequency_Hz * 20.0 * Ts <= 1.0)) {
      os << describe(p) << ": frequency must be in (0, " << 1.0 / (20.0 * Ts)
         << "] Hz (at least 20 samples per period)";
      throw ConfigError(key, os.str());
    }
    if (!(p.settle_s >= 0.0)) throw ConfigError(key, describe(p) + ": settling time must be >= 0");
    if (p.periods < kMinPeriods) {
      os << describe(p) << ": " << p.periods << " periods are too few (at least " << kMinPeriods
         << " for a spread estimate)";
      throw ConfigError(key, os.str());
    }
  }
}

ExcitationPlan ExcitationPlan::from_grid(const Grid& g, double Ts, double vmin, double vmax) {
  if (g.amplitudes_V.empty() || g.biases_V.empty() || g.frequency_count < 1)
    throw ConfigError("ident.plan", "the grid needs at least one amplitude, bias and frequency");
  if (!(g.frequency_min_Hz > 0.0 && g.frequency_max_Hz >= g.frequency_min_Hz))
    throw ConfigError("ident.plan", "need 0 < frequency_min_Hz <= frequency_max_Hz");
  if (!(g.min_analysed_s >= 0.0)) throw ConfigError("ident.plan", "min_analysed_s must be >= 0");
  std::vector<SinePoint> pts;
  for (double A : g.amplitudes_V)
    for (double B : g.biases_V)
      for (double f : log_spaced(g.frequency_min_Hz, g.frequency_max_Hz, g.frequency_count)) {
        SinePoint p;
        p.amplitude_V = A;
        p.bias_V = B;
        p.frequency_Hz = f;
        p.settle_s = g.settle_s;
        p.periods = std::max(g.min_periods, static_cast<int>(std::ceil(g.min_analysed_s * f - 1e-9)));
        pts.push_back(p);
      }
  return ExcitationPlan(std::move(pts), Ts, vmin, vmax);
}

double ExcitationPlan::total_duration_s() const noexcept {
  double s = 0.0;
  for (const auto& p : points_) s += p.duration_s();
  return s;
}

std::vector<double> log_spaced(double min, double max, int count) {
  std::vector<double> v;
  if (count <= 1) return {min};
  for (int i = 0; i < count; ++i) v.push_back(min * std::pow(max / min, static_cast<double>(i) / (count - 1)));
  v.back() = max;
  return v;
}

}  // namespace pvcgel::control::identification
