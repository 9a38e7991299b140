#include "control/diagnosis/mode_hint.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <unsupported/Eigen/FFT>

#include "control/diagnosis/fit_problem.hpp"

namespace pvcgel::control::diagnosis::detail {

namespace {

constexpr double kGridStep = 1.01;        ///< log-frequency grid: 1% apart (a mode with zeta 0.005 is 1% wide)
constexpr double kResidualOverNoise = 10.0;  ///< a peak's residual power over the noise's (pooled per grid cell)
constexpr double kNoiseGuard = 10.0;       ///< the noise's power added to the prediction's in the ratio
/// A peak's error transfer |r| / |yhat| squared: the residual at least 0.7 of the prediction there,
/// what a lightly damped mode leaves near its frequency ((1 - direct_fraction) / (2 zeta) >= 0.7), and not
/// a lag (on tuning case058, a delay and a slew limit left 0.33 at a drive tone, and a mode started there
/// took the delay's place). At 1 (the residual as large as the prediction) evaluation case194's 34 Hz
/// mode, 2.6% of a 5 kHz piezo's stroke rung by steps, left 0.96 and went unfound (`unexplained`).
constexpr double kMinErrorTransfer = 0.5;
constexpr double kPeakApart = 1.05;       ///< peaks closer than 5% in frequency are one
constexpr size_t kMinRangeSamples = 64;   ///< a fit range shorter than this resolves no mode

/// Residual and prediction power pooled on the log-frequency grid, with the noise's share of the first.
struct PooledSpectra {
  std::vector<double> residual, prediction, noise;
  explicit PooledSpectra(size_t n) : residual(n, 0.0), prediction(n, 0.0), noise(n, 0.0) {}
};

/// The largest length up to n whose only prime factors are 2, 3 and 5: a transform of a length with a large
/// prime factor is quadratic (a 62497-sample range of a 10 kHz rig took 7 s, against 10 ms).
size_t fast_transform_length(size_t n) {
  size_t best = 1;
  for (size_t p2 = 1; p2 <= n; p2 *= 2)
    for (size_t p3 = p2; p3 <= n; p3 *= 3)
      for (size_t p5 = p3; p5 <= n; p5 *= 5) best = std::max(best, p5);
  return best;
}

/// Adds one fit range [b, e) of recording `s` to `pool`: Hann-windowed transforms of the residual and
/// the prediction (its mean removed) over the range's first fast_transform_length samples, each bin
/// pooled into the grid cell of its frequency.
void add_range(PooledSpectra& pool, const Series& s, const std::vector<double>& yhat, size_t b, size_t e,
               double sigma_um, double f_min_Hz) {
  const size_t n = fast_transform_length(e - b);
  e = b + n;
  double mean = 0.0;
  for (size_t k = b; k < e; ++k) mean += yhat[k];
  mean /= static_cast<double>(n);
  std::vector<double> r(n), p(n);
  double window_power = 0.0;
  for (size_t k = 0; k < n; ++k) {
    const double w = 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(n));
    r[k] = w * (s.y_um[b + k] - yhat[b + k]);
    p[k] = w * (yhat[b + k] - mean);
    window_power += w * w;
  }
  Eigen::FFT<double> fft;
  std::vector<std::complex<double>> R, P;
  fft.fwd(R, r);
  fft.fwd(P, p);
  const double df = 1.0 / (static_cast<double>(n) * s.sample_time_s);
  const double noise_per_bin = sigma_um * sigma_um * window_power;
  for (size_t i = 1; i < n / 2; ++i) {
    const double f = static_cast<double>(i) * df;
    if (f < f_min_Hz) continue;
    const auto cell = static_cast<size_t>(std::floor(std::log(f / f_min_Hz) / std::log(kGridStep)));
    if (cell >= pool.residual.size()) break;
    pool.residual[cell] += std::norm(R[i]);
    pool.prediction[cell] += std::norm(P[i]);
    pool.noise[cell] += noise_per_bin;
  }
}

}  // namespace

std::vector<double> mode_frequency_hints(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat,
                                         const std::vector<std::vector<char>>& held_out, double sigma_um,
                                         double f_min_Hz, double f_max_Hz, size_t count) {
  if (!(f_max_Hz > f_min_Hz && f_min_Hz > 0.0 && sigma_um > 0.0)) return {};
  const auto cells = static_cast<size_t>(std::ceil(std::log(f_max_Hz / f_min_Hz) / std::log(kGridStep)));
  PooledSpectra pool(cells);
  for (size_t r = 0; r < data.size(); ++r)
    for (const auto& [b, e] : fit_ranges(held_out[r]))
      if (e - b >= kMinRangeSamples) add_range(pool, data[r], yhat[r], b, e, sigma_um, f_min_Hz);
  // The error transfer |r|^2 / |yhat|^2, its noise removed and its denominator kept off the noise: a mode
  // rung by little input (a tone's leakage, a step) is all residual and nearly no prediction.
  std::vector<double> ratio(cells, 0.0);
  for (size_t c = 0; c < cells; ++c)
    if (pool.residual[c] > kResidualOverNoise * pool.noise[c])
      ratio[c] = (pool.residual[c] - pool.noise[c]) / (pool.prediction[c] + kNoiseGuard * pool.noise[c]);
  std::vector<std::pair<double, double>> peaks;  // (ratio, frequency)
  for (size_t c = 0; c < cells; ++c) {
    const bool local_max = ratio[c] > 0.0 && (c == 0 || ratio[c] >= ratio[c - 1]) && (c + 1 == cells || ratio[c] > ratio[c + 1]);
    if (local_max) peaks.emplace_back(ratio[c], f_min_Hz * std::pow(kGridStep, static_cast<double>(c) + 0.5));
  }
  std::sort(peaks.begin(), peaks.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<double> out;
  for (const auto& [ratio_at, f] : peaks) {
    if (out.size() == count || ratio_at < kMinErrorTransfer) break;
    // Neighbouring cells of one peak (a tone's bins fall into every few cells at low frequencies).
    const bool apart = std::none_of(out.begin(), out.end(), [&](double g) { return std::abs(std::log(f / g)) < std::log(kPeakApart); });
    if (apart) out.push_back(f);
  }
  return out;
}

}  // namespace pvcgel::control::diagnosis::detail
