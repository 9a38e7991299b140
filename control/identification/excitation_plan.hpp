#pragma once
/// @file
/// The sine experiments of a describing-function identification (paper Section V-B).

#include <vector>

namespace pvcgel::control::identification {

/// One sine experiment: `u(t) = B + A sin(2 pi f t)` from t = 0, held for a
/// settling time and then for a whole number of periods that are analysed.
struct SinePoint {
  double amplitude_V = 300.0;  ///< A
  double bias_V = 450.0;       ///< B
  double frequency_Hz = 1.0;   ///< f
  double settle_s = 10.0;      ///< start-up transient, not analysed
  int periods = 4;             ///< whole periods analysed after the settling time

  /// Length of the whole experiment.
  [[nodiscard]] double duration_s() const noexcept { return settle_s + periods / frequency_Hz; }
  /// The commanded voltage at time t (from the start of the experiment).
  [[nodiscard]] double voltage_V(double t_s) const noexcept;
};

/// A validated list of sine experiments. Every point stays inside
/// `voltage_min_V..voltage_max_V` (the amplifier's 0..1000 V: below 0 the
/// electrodes swap roles, above 1000 V the gel is damaged), is sampled with at
/// least 20 samples per period, and has enough periods for a spread estimate.
class ExcitationPlan final {
 public:
  /// The grid the plan is built from; defaults are the paper's (Section V-B).
  struct Grid {
    std::vector<double> amplitudes_V{300.0, 350.0, 400.0};
    std::vector<double> biases_V{400.0, 450.0, 500.0};
    double frequency_min_Hz = 0.1;
    double frequency_max_Hz = 10.0;
    int frequency_count = 7;  ///< log-spaced between min and max (inclusive)
    /// 10 s is five times the slowest time constant of the paper's G (1.9 s).
    double settle_s = 10.0;
    /// At least this many periods per point, and at least `min_analysed_s` of
    /// analysed data (more periods at high frequency average the noise down).
    int min_periods = 4;
    double min_analysed_s = 10.0;
  };

  /// Smallest number of analysed periods a point may have (a spread needs several).
  static constexpr int kMinPeriods = 3;

  /// @throws ConfigError ("ident.plan") naming the offending point.
  ExcitationPlan(std::vector<SinePoint> points, double sample_time_s, double voltage_min_V = 0.0,
                 double voltage_max_V = 1000.0);

  /// All amplitudes x biases x frequencies of `grid`, in that nesting order.
  /// @throws ConfigError ("ident.plan") on an invalid grid or point.
  static ExcitationPlan from_grid(const Grid& grid, double sample_time_s, double voltage_min_V = 0.0,
                                  double voltage_max_V = 1000.0);

  [[nodiscard]] const std::vector<SinePoint>& points() const noexcept { return points_; }
  [[nodiscard]] double sample_time_s() const noexcept { return sample_time_s_; }
  /// Sum of all experiment durations.
  [[nodiscard]] double total_duration_s() const noexcept;

 private:
  std::vector<SinePoint> points_;
  double sample_time_s_;
};

/// `count` log-spaced values from `min` to `max` inclusive (count 1: min).
std::vector<double> log_spaced(double min, double max, int count);

}  // namespace pvcgel::control::identification
