#include "control/diagnosis/significance.hpp"

#include <boost/math/distributions/students_t.hpp>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>

namespace pvcgel::control::diagnosis::detail {

namespace {

/// Upper quantile of the standard normal: z with P(Z > z) = p.
double normal_upper_quantile(double p) {
  double lo = 0.0, hi = 40.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (0.5 * std::erfc(mid / std::sqrt(2.0)) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// Ljung-Box statistic of `r` over lags 1..m (chi-square(m) for white noise).
double ljung_box(const std::vector<double>& r, int m) {
  const size_t n = r.size();
  const double mean = std::accumulate(r.begin(), r.end(), 0.0) / static_cast<double>(n);
  double c0 = 0.0;
  for (double v : r) c0 += (v - mean) * (v - mean);
  double q = 0.0;
  for (int lag = 1; lag <= m && static_cast<size_t>(lag) < n; ++lag) {
    double c = 0.0;
    for (size_t k = static_cast<size_t>(lag); k < n; ++k) c += (r[k] - mean) * (r[k - static_cast<size_t>(lag)] - mean);
    const double rho = c / std::max(c0, 1e-300);
    q += rho * rho / static_cast<double>(n - static_cast<size_t>(lag));
  }
  return static_cast<double>(n) * static_cast<double>(n + 2) * q;
}

}  // namespace

double chi2_mean_upper_quantile(double n, double p) {
  const double v = 2.0 / (9.0 * n), z = normal_upper_quantile(p);
  return std::pow(1.0 - v + z * std::sqrt(v), 3.0);
}

size_t window_samples(const Series& s, const DiagnosisOptions& o) {
  return std::max<size_t>(50, static_cast<size_t>(std::lround(o.window_s / s.sample_time_s)));
}

WindowLevel window_level(const std::vector<Series>& data, const DiagnosisOptions& o) {
  WindowLevel l;
  size_t total = 0;
  for (const auto& s : data) {
    l.windows += static_cast<int>(std::max<size_t>(1, s.y_um.size() / window_samples(s, o)));
    total += s.y_um.size();
  }
  // Relative standard error of a median-based sigma from `total` samples is ~1.17/sqrt(N): its
  // one-sided 99% bound widens the variance threshold by 2 * 2.33 * that.
  l.sigma_margin = 1.0 + 2.0 * 2.33 * 1.17 / std::sqrt(static_cast<double>(total));
  return l;
}

/// The `none` test on residuals: every window's mean square against the noise
/// variance (`WindowLevel`), and Ljung-Box whiteness per recording
/// (Bonferroni over the recordings). Half the false-alarm rate goes to each.
NoneTest none_test(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat, double sigma,
                   const DiagnosisOptions& o) {
  NoneTest t;
  t.false_alarm_rate = o.false_alarm_rate;
  const auto level = window_level(data, o);
  t.windows = level.windows;
  constexpr int kLags = 10;
  t.whiteness_threshold = kLags * chi2_mean_upper_quantile(kLags, 0.5 * o.false_alarm_rate / static_cast<double>(data.size()));
  for (size_t r = 0; r < data.size(); ++r) {
    const auto& s = data[r];
    const size_t w = window_samples(s, o);
    std::vector<double> res(s.y_um.size());
    for (size_t k = 0; k < res.size(); ++k) res[k] = s.y_um[k] - yhat[r][k];
    for (size_t b = 0; b + w / 2 < res.size(); b += w) {
      const size_t e = std::min(b + w, res.size());
      double ss = 0.0;
      for (size_t k = b; k < e; ++k) ss += res[k] * res[k];
      const double n = static_cast<double>(e - b), ratio = ss / n / (sigma * sigma);
      const double thr = level.threshold(n, o);
      if (ratio / thr > t.worst_window_ratio / std::max(t.window_threshold, 1e-300) || t.window_threshold == 0.0) {
        t.worst_window_ratio = ratio;
        t.window_threshold = thr;
      }
    }
    t.whiteness_q = std::max(t.whiteness_q, ljung_box(res, kLags));
  }
  t.level_ok = t.worst_window_ratio <= t.window_threshold;
  t.white = t.whiteness_q <= t.whiteness_threshold;
  return t;
}

double noise_sigma(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat) {
  std::vector<double> sigmas;
  for (size_t r = 0; r < data.size(); ++r) {
    std::vector<double> e(data[r].y_um.size());
    for (size_t i = 0; i < e.size(); ++i) e[i] = data[r].y_um[i] - yhat[r][i];
    sigmas.push_back(estimate_noise_sigma(e));
  }
  std::sort(sigmas.begin(), sigmas.end());
  return std::max(sigmas[sigmas.size() / 2], 1e-12);
}

}  // namespace pvcgel::control::diagnosis::detail

namespace pvcgel::control::diagnosis {

double estimate_noise_sigma(const std::vector<double>& y) {
  if (y.size() < 8) return 0.0;
  std::vector<double> d;
  d.reserve(y.size());
  for (size_t k = 2; k < y.size(); ++k) d.push_back(std::abs(y[k] - 2.0 * y[k - 1] + y[k - 2]));
  std::vector<double> sorted = d;
  auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), mid, sorted.end());
  // White noise: var(second difference) = 6 sigma^2. The mean |d| (E|N(0,1)| = sqrt(2/pi)) over the
  // values below 5 medians ignores steps and spikes, and unlike the median it does not snap to the
  // quantisation steps of a quantised sensor.
  const double cap = *mid > 0.0 ? 5.0 * *mid : INFINITY;
  double sum = 0.0, n = 0.0;
  for (double v : d)
    if (v <= cap) sum += v, n += 1.0;
  return n > 0.0 ? sum / n * std::sqrt(std::numbers::pi / 2.0) / std::sqrt(6.0) : 0.0;
}

namespace {

/// One block of held-out samples: the mean squared-error reduction and the mean squared difference of
/// the two predictions (how much the block can tell them apart at all).
struct HeldOutBlock {
  double gain_um2 = 0.0, difference_um2 = 0.0;
};

/// Blocks of contiguous held-out samples: a model error is correlated in time, so single samples would
/// overstate the evidence; blocks of the localisation window are nearly independent for the dynamics here.
/// A stretch's remnant under half a block joins the stretch's last block: dropped, it can hold most of an
/// effect's evidence (a slew limit seen in the last second of a held-out stretch).
std::vector<HeldOutBlock> held_out_blocks(const std::vector<Series>& data, const std::vector<std::vector<double>>& y_a,
                                          const std::vector<std::vector<double>>& y_b,
                                          const std::vector<std::vector<char>>& held_out, double block_s) {
  std::vector<HeldOutBlock> blocks;
  for (size_t r = 0; r < data.size(); ++r) {
    const size_t len = std::max<size_t>(10, static_cast<size_t>(std::lround(block_s / data[r].sample_time_s)));
    HeldOutBlock sum;
    size_t n = 0;
    bool stretch_has_block = false;
    for (size_t k = 0; k <= data[r].y_um.size(); ++k) {
      const bool in = k < data[r].y_um.size() && held_out[r][k];
      if (in) {
        const double ea = data[r].y_um[k] - y_a[r][k], eb = data[r].y_um[k] - y_b[r][k];
        sum.gain_um2 += ea * ea - eb * eb;
        sum.difference_um2 += (y_a[r][k] - y_b[r][k]) * (y_a[r][k] - y_b[r][k]);
        ++n;
      }
      const double dn = static_cast<double>(n);
      if (n > 0 && (n == len || (!in && n >= len / 2))) {
        blocks.push_back({sum.gain_um2 / dn, sum.difference_um2 / dn});
        stretch_has_block = true;
      } else if (n > 0 && !in && stretch_has_block) {
        HeldOutBlock& last = blocks.back();
        const double dl = static_cast<double>(len);
        last.gain_um2 = (last.gain_um2 * dl + sum.gain_um2) / (dl + dn);
        last.difference_um2 = (last.difference_um2 * dl + sum.difference_um2) / (dl + dn);
      }
      if (!in) stretch_has_block = false;
      if (n == len || !in) sum = {}, n = 0;
    }
  }
  return blocks;
}

/// Twice the rank of each |v| (average ranks on ties are then whole), so the exact distribution is over integers.
std::vector<size_t> doubled_ranks(const std::vector<double>& v) {
  const size_t n = v.size();
  std::vector<size_t> order(n), rank2(n);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return std::abs(v[a]) < std::abs(v[b]); });
  for (size_t i = 0; i < n;) {
    size_t j = i;
    while (j + 1 < n && std::abs(v[order[j + 1]]) == std::abs(v[order[i]])) ++j;
    for (size_t k = i; k <= j; ++k) rank2[order[k]] = i + j + 2;
    i = j + 1;
  }
  return rank2;
}

/// P(sum of a random subset of `rank2` >= w), each rank in with probability 1/2, independently (by DP).
double exact_upper_tail(const std::vector<size_t>& rank2, size_t w) {
  const size_t total = std::accumulate(rank2.begin(), rank2.end(), size_t{0});
  std::vector<double> p(total + 1, 0.0);
  p[0] = 1.0;
  size_t reach = 0;
  for (size_t r : rank2) {
    for (size_t s = reach + 1; s-- > 0;) {
      p[s + r] += 0.5 * p[s];
      p[s] *= 0.5;
    }
    reach += r;
  }
  return w > total ? 0.0 : std::accumulate(p.begin() + static_cast<std::ptrdiff_t>(w), p.end(), 0.0);
}

}  // namespace

double signed_rank_p(const std::vector<double>& x) {
  std::vector<double> v;
  for (double g : x)
    if (g != 0.0) v.push_back(g);
  if (v.empty()) return 1.0;
  const auto rank2 = doubled_ranks(v);
  size_t w = 0;
  for (size_t i = 0; i < v.size(); ++i)
    if (v[i] > 0.0) w += rank2[i];
  if (v.size() <= 300) return exact_upper_tail(rank2, w);
  // The normal approximation, with continuity correction (a step of 2 in doubled units).
  double mean = 0.0, var = 0.0;
  for (size_t r : rank2) mean += 0.5 * static_cast<double>(r), var += 0.25 * static_cast<double>(r * r);
  const double z = (static_cast<double>(w) - mean - 1.0) / std::sqrt(var);
  return 0.5 * std::erfc(z / std::sqrt(2.0));
}

HeldOutTest held_out_improvement(const std::vector<Series>& data, const std::vector<std::vector<double>>& y_a,
                                 const std::vector<std::vector<double>>& y_b, const std::vector<std::vector<char>>& held_out,
                                 double block_s, double level, double indistinct_um2) {
  const auto blocks = held_out_blocks(data, y_a, y_b, held_out, block_s);
  HeldOutTest t;
  std::vector<double> gains;
  for (const auto& b : blocks) {
    t.mean_um2 += b.gain_um2 / static_cast<double>(blocks.size());
    if (b.difference_um2 >= indistinct_um2) gains.push_back(b.gain_um2);
  }
  t.blocks = static_cast<int>(gains.size());
  if (gains.size() < 3) return t;
  // The t statistic over the blocks that can tell the models apart: a block where both predict the same
  // adds nothing to the evidence but dilutes its mean (an effect seen only after a few steps).
  const double nb = static_cast<double>(gains.size());
  const double mean = std::accumulate(gains.begin(), gains.end(), 0.0) / nb;
  double var = 0.0;
  for (double g : gains) var += (g - mean) * (g - mean);
  const double se = std::sqrt(var / (nb - 1.0) / nb);
  t.t = se > 0.0 ? mean / se : (mean > 0.0 ? INFINITY : 0.0);
  // Two tests, each at half the level (Bonferroni): the t test sees a gain confined to a few blocks; the
  // signed-rank test a gain in nearly every block whose size varies by orders of magnitude (a saturation
  // that matters most at the peaks), where the largest blocks inflate the t test's standard error.
  t.threshold = boost::math::quantile(boost::math::complement(boost::math::students_t(nb - 1.0), 0.5 * level));
  t.signed_rank_p = signed_rank_p(gains);
  t.significant = t.t > t.threshold || t.signed_rank_p < 0.5 * level;
  return t;
}

}  // namespace pvcgel::control::diagnosis
