#pragma once
/// @file
/// The diagnosis's statistical tests (internal): the `none` test on a residual (each window's level
/// against the noise, Bonferroni over the windows, and whiteness), and the noise estimate it rests on.
/// The held-out test of one model against another is public (diagnosis.hpp: held_out_improvement).

#include <cstddef>
#include <vector>

#include "control/diagnosis/diagnosis.hpp"

namespace pvcgel::control::diagnosis::detail {

/// Upper quantile of chi-square(n) / n at tail probability p (Wilson-Hilferty).
double chi2_mean_upper_quantile(double n, double p);

/// Samples in one localisation window of `s` (o.window_s, at least 50).
size_t window_samples(const Series& s, const DiagnosisOptions& o);

/// The `none` test's threshold on one window's mean square over the noise variance: chi-square for the
/// window's samples, Bonferroni over all the recordings' windows, with a margin for the uncertainty of the
/// noise estimate.
struct WindowLevel {
  int windows = 0;
  double sigma_margin = 1.0;
  [[nodiscard]] double threshold(double n, const DiagnosisOptions& o) const {
    return chi2_mean_upper_quantile(n, 0.5 * o.false_alarm_rate / windows) * sigma_margin;
  }
};

/// The window count and noise-estimate margin of `data` (WindowLevel).
WindowLevel window_level(const std::vector<Series>& data, const DiagnosisOptions& o);

/// The `none` test on the residual of `yhat` against the noise `sigma`.
NoneTest none_test(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat, double sigma,
                   const DiagnosisOptions& o);

/// Sensor noise: the median over recordings of the noise estimated from each one's residual.
double noise_sigma(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat);

}  // namespace pvcgel::control::diagnosis::detail
