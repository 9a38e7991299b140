#include "control/diagnosis/diagnosis.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <stdexcept>

#include "control/config_error.hpp"

namespace pvcgel::control::diagnosis {

namespace {

std::string fmt(const char* f, double a) {
  char b[64];
  std::snprintf(b, sizeof b, f, a);
  return b;
}

/// Sum of squared residuals over [begin, end) and the count.
struct SquaredError {
  double sum = 0.0;
  double n = 0.0;
  void add(double r) {
    sum += r * r;
    n += 1.0;
  }
  [[nodiscard]] double mse() const { return n > 0 ? sum / n : 0.0; }
};

/// Internal (fit) coordinates: log for scale parameters, range-normalised otherwise.
struct Coordinates {
  std::vector<ParameterSpec> specs;
  [[nodiscard]] double scale(size_t i) const { return (specs[i].upper - specs[i].lower) / 100.0; }
  [[nodiscard]] double to_z(size_t i, double p) const {
    return specs[i].log_scale ? std::log(p) : p / scale(i);
  }
  [[nodiscard]] double to_p(size_t i, double z) const {
    const double p = specs[i].log_scale ? std::exp(z) : z * scale(i);
    return std::clamp(p, specs[i].lower, specs[i].upper);
  }
};

/// Puts `plant` at rest where it explains the first measured samples.
double rest_at_start(AugmentedPlant& plant, const Series& s) {
  // Intercept of a line through the first 10 samples: the recording may start moving at once.
  const size_t n = std::min<size_t>(10, s.y_um.size());
  double sk = 0, sy = 0, skk = 0, sky = 0;
  for (size_t k = 0; k < n; ++k) {
    const double kk = static_cast<double>(k);
    sk += kk;
    sy += s.y_um[k];
    skk += kk * kk;
    sky += kk * s.y_um[k];
  }
  const double N = static_cast<double>(n);
  const double slope = n > 1 ? (N * sky - sk * sy) / (N * skk - sk * sk) : 0.0;
  const double y0 = (sy - slope * sk) / N;
  const auto [lo, hi] = std::minmax_element(s.u_V.begin(), s.u_V.end());
  return plant.rest_voltage(y0, *lo - 200.0, *hi + 200.0);
}

class Problem {
 public:
  Problem(const HammersteinModel& m, const std::vector<Series>& d, const std::vector<std::vector<char>>& held_out, int io)
      : model_(m), data_(d), held_out_(held_out), io_(io) {
    for (const auto& mask : held_out) {
      n_fit_ += static_cast<size_t>(std::count(mask.begin(), mask.end(), 0));
      size_t last = 0;
      for (size_t k = 0; k < mask.size(); ++k)
        if (!mask[k]) last = k + 1;
      end_.push_back(last);
    }
  }

  /// Fit-segment residual of `e`; simulates only up to the end of each fit segment.
  Eigen::VectorXd residual(const Effect& e) {
    ++simulations_;
    Eigen::VectorXd out(static_cast<Eigen::Index>(n_fit_));
    Eigen::Index j = 0;
    for (size_t r = 0; r < data_.size(); ++r) {
      const auto& s = data_[r];
      AugmentedPlant plant(model_, io_, s.sample_time_s, e);
      rest_at_start(plant, s);
      for (size_t k = 0; k < end_[r]; ++k) {
        if (!held_out_[r][k]) out(j++) = s.y_um[k] - plant.output();
        plant.apply(s.u_V[k]);
      }
    }
    return out;
  }
  [[nodiscard]] int simulations() const { return simulations_; }

 private:
  const HammersteinModel& model_;
  const std::vector<Series>& data_;
  const std::vector<std::vector<char>>& held_out_;
  std::vector<size_t> end_;  ///< one past the last fitted sample, per recording
  int io_;
  size_t n_fit_ = 0;
  int simulations_ = 0;
};

Effect make_effect(EffectKind kind, const Coordinates& c, const Eigen::VectorXd& z) {
  Effect e{kind, {}};
  for (size_t i = 0; i < c.specs.size(); ++i) e.p[i] = c.to_p(i, z(static_cast<Eigen::Index>(i)));
  return e;
}

/// Bounded Levenberg-Marquardt on the simulated output, numerical Jacobian.
Eigen::VectorXd levenberg_marquardt(Problem& problem, EffectKind kind, const Coordinates& c, Eigen::VectorXd z,
                                    double& cost) {
  const auto n = z.size();
  Eigen::VectorXd r = problem.residual(make_effect(kind, c, z));
  cost = r.squaredNorm();
  double lambda = 1e-2;
  for (int iter = 0; iter < 25; ++iter) {
    Eigen::MatrixXd J(r.size(), n);
    for (Eigen::Index i = 0; i < n; ++i) {
      Eigen::VectorXd zh = z;
      const double h = 1e-3;
      zh(i) += h;
      // At an upper bound, difference backwards so the step is not clamped away.
      const double p_plus = c.to_p(static_cast<size_t>(i), zh(i));
      if (p_plus == c.to_p(static_cast<size_t>(i), z(i))) zh(i) = z(i) - h;
      J.col(i) = (r - problem.residual(make_effect(kind, c, zh))) / (zh(i) - z(i));  // d(yhat)/dz
    }
    const Eigen::MatrixXd JtJ = J.transpose() * J;
    const Eigen::VectorXd Jtr = J.transpose() * r;
    bool improved = false;
    while (lambda < 1e10) {
      Eigen::MatrixXd Aug = JtJ;
      for (Eigen::Index i = 0; i < n; ++i) Aug(i, i) += lambda * std::max(JtJ(i, i), 1e-12);
      Eigen::VectorXd z_new = z + Aug.ldlt().solve(Jtr);
      for (Eigen::Index i = 0; i < n; ++i)
        z_new(i) = c.to_z(static_cast<size_t>(i), c.to_p(static_cast<size_t>(i), z_new(i)));
      const Eigen::VectorXd r_new = problem.residual(make_effect(kind, c, z_new));
      const double cost_new = r_new.squaredNorm();
      if (cost_new < cost) {
        const double gain = (cost - cost_new) / cost;
        z = z_new;
        r = r_new;
        cost = cost_new;
        lambda = std::max(lambda / 4.0, 1e-7);
        improved = gain > 1e-7;
        break;
      }
      lambda *= 5.0;
    }
    if (!improved) break;
  }
  return z;
}

ModelErrors errors_of(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat,
                      const std::vector<std::vector<char>>& held_out) {
  SquaredError all, fit, val;
  for (size_t r = 0; r < data.size(); ++r)
    for (size_t k = 0; k < data[r].y_um.size(); ++k) {
      const double e = data[r].y_um[k] - yhat[r][k];
      all.add(e);
      (held_out[r][k] ? val : fit).add(e);
    }
  return {std::sqrt(all.mse()), std::sqrt(fit.mse()), std::sqrt(val.mse())};
}

std::string parameters_text(const Effect& e, const std::vector<ParameterSpec>& specs) {
  std::string s;
  for (size_t i = 0; i < specs.size(); ++i) s += (i ? ", " : "") + specs[i].name + " = " + fmt("%.4g", e.p[i]);
  return s;
}

/// Starting points that depend on the data: a slew limit only matters below
/// the fastest recorded voltage rate, a dead zone only where |u| comes low.
void add_data_starts(EffectKind kind, std::vector<ParameterSpec>& specs, const std::vector<Series>& data) {
  if (kind == EffectKind::slew_limit) {
    double rate = 0.0;
    for (const auto& s : data)
      for (size_t k = 1; k < s.u_V.size(); ++k) rate = std::max(rate, std::abs(s.u_V[k] - s.u_V[k - 1]) / s.sample_time_s);
    for (double q : {0.25, 0.4, 0.55, 0.7, 0.8, 0.9, 0.95, 0.98})
      if (q * rate > specs[0].lower) specs[0].starts.push_back(q * rate);
  } else if (kind == EffectKind::dead_zone) {
    std::vector<double> a;
    for (const auto& s : data)
      for (double u : s.u_V) a.push_back(std::abs(u));
    auto q = a.begin() + static_cast<std::ptrdiff_t>(a.size() / 50);
    std::nth_element(a.begin(), q, a.end());
    const double u_lo = *q;
    if (u_lo < 1.0) return;
    for (double f : {0.1, 0.3, 0.6}) specs[0].starts.push_back(f * u_lo);
    for (double f : {0.3, 0.7, 1.0, 1.3}) specs[1].starts.push_back(f * u_lo);
  }
}

}  // namespace

std::vector<char> held_out_mask(size_t n, double Ts, const DiagnosisOptions& o) {
  auto block = static_cast<size_t>(std::lround(o.validation_block_s / Ts));
  if (block == 0 || n < 2 * block) block = n;
  const auto fitted = static_cast<size_t>(std::lround((1.0 - o.validation_fraction) * static_cast<double>(block)));
  std::vector<char> mask(n);
  for (size_t k = 0; k < n; ++k) mask[k] = (k % block) >= fitted ? 1 : 0;
  return mask;
}

double estimate_noise_sigma(const std::vector<double>& y) {
  if (y.size() < 8) return 0.0;
  std::vector<double> d;
  d.reserve(y.size());
  for (size_t k = 2; k < y.size(); ++k) d.push_back(std::abs(y[k] - 2.0 * y[k - 1] + y[k - 2]));
  auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
  std::nth_element(d.begin(), mid, d.end());
  // White noise: var(second difference) = 6 sigma^2; median |N(0,1)| = 0.6745.
  return *mid / 0.6745 / std::sqrt(6.0);
}

std::string describe_regime(const Series& s, size_t b, size_t e) {
  if (e <= b) return "";
  double lo = s.u_V[b], hi = s.u_V[b], sum = 0.0;
  long rising = 0, falling = 0, reversals = 0;
  int dir = 0;
  double anchor = s.u_V[b];
  const auto [mn, mx] = std::minmax_element(s.u_V.begin() + static_cast<std::ptrdiff_t>(b), s.u_V.begin() + static_cast<std::ptrdiff_t>(e));
  const double band = std::max(1.0, 0.1 * (*mx - *mn));
  for (size_t k = b; k < e; ++k) {
    lo = std::min(lo, s.u_V[k]);
    hi = std::max(hi, s.u_V[k]);
    sum += s.u_V[k];
    if (k > b) {
      if (s.u_V[k] > s.u_V[k - 1]) ++rising;
      else if (s.u_V[k] < s.u_V[k - 1]) ++falling;
    }
    // Direction reversals with a band, so noise on u (closed loop) does not count.
    if (s.u_V[k] > anchor + band) {
      if (dir < 0) ++reversals;
      dir = 1;
      anchor = s.u_V[k];
    } else if (s.u_V[k] < anchor - band) {
      if (dir > 0) ++reversals;
      dir = -1;
      anchor = s.u_V[k];
    } else if ((dir > 0 && s.u_V[k] > anchor) || (dir < 0 && s.u_V[k] < anchor)) {
      anchor = s.u_V[k];
    }
  }
  const double dur = static_cast<double>(e - b) * s.sample_time_s;
  const double moving = static_cast<double>(rising + falling);
  std::string r = "u " + fmt("%.0f", lo) + ".." + fmt("%.0f", hi) + " V (mean " +
                  fmt("%.0f", sum / static_cast<double>(e - b)) + " V, amplitude " + fmt("%.0f", (hi - lo) / 2) + " V)";
  if (moving == 0 || hi - lo < 1.0) return r + ", held";
  r += ", rising " + fmt("%.0f", 100.0 * static_cast<double>(rising) / moving) + "% of moving samples";
  const double f = static_cast<double>(reversals) / (2.0 * dur);
  r += reversals > 0 ? ", ~" + fmt("%.2g", f) + " Hz" : (rising > falling ? ", rising ramp/step" : ", falling ramp/step");
  return r;
}

void check_series(const Series& s, const HammersteinModel& model) {
  const size_t n = s.t_s.size();
  if (s.u_V.size() != n || s.y_um.size() != n) throw std::invalid_argument("t_s, u_V and y_um differ in length");
  if (n < 3) throw std::invalid_argument("fewer than 3 samples");
  const double Ts = s.sample_time_s;
  for (size_t k = 0; k < n; ++k) {
    if (!std::isfinite(s.t_s[k]) || !std::isfinite(s.u_V[k]) || !std::isfinite(s.y_um[k]))
      throw std::invalid_argument("sample " + std::to_string(k) + ": non-finite t_s, u_V or y_um");
    if (k > 0) {
      const double dt = s.t_s[k] - s.t_s[k - 1];
      if (!(dt > 0)) throw std::invalid_argument("sample " + std::to_string(k) + ": time does not increase");
      if (std::abs(dt - Ts) > 0.01 * Ts)
        throw std::invalid_argument("sample " + std::to_string(k) + ": non-uniform sampling (step " +
                                    fmt("%.6g", dt) + " s, expected " + fmt("%.6g", Ts) + " s)");
    }
  }
  double slowest = 0.0;
  for (const auto& p : model.G.poles()) slowest = std::max(slowest, -1.0 / p.real());
  const double dur = static_cast<double>(n - 1) * Ts;
  if (dur < 3.0 * slowest)
    throw std::invalid_argument("recording lasts " + fmt("%.3g", dur) + " s, shorter than 3 time constants of G's slowest pole (" +
                                fmt("%.3g", 3.0 * slowest) + " s): the output-error simulation cannot be judged");
}

std::vector<std::vector<double>> simulate(const HammersteinModel& model, const Effect& effect,
                                          const std::vector<Series>& data, int io) {
  std::vector<std::vector<double>> out;
  for (const auto& s : data) {
    AugmentedPlant plant(model, io, s.sample_time_s, effect);
    out.push_back(plant.simulate(s.u_V, rest_at_start(plant, s)));
  }
  return out;
}

DiagnosisResult diagnose(const HammersteinModel& model, const std::vector<Series>& data, const DiagnosisOptions& o) {
  if (data.empty()) throw std::invalid_argument("no recordings");
  if (!model.G.is_stable()) throw ConfigError("model.G", "G(s) = " + model.G.to_string() + " is unstable");
  double u_max = 0.0, duration = 0.0;
  for (const auto& s : data) {
    check_series(s, model);
    for (double u : s.u_V) u_max = std::max(u_max, std::abs(u));
    duration = std::max(duration, s.t_s.back() - s.t_s.front());
  }
  if (const auto turn = model.f.first_turnover(std::max(u_max, 1.0)))
    throw ConfigError("model.poly", "f is not monotone: f'(x) reaches 0 at x = " + fmt("%.1f", *turn) +
                                        " V, inside the recorded voltage range (|u| up to " + fmt("%.1f", u_max) + " V)");

  DiagnosisResult res;
  for (const auto& s : data) res.held_out.push_back(held_out_mask(s.u_V.size(), s.sample_time_s, o));
  const auto& split = res.held_out;

  // 1. Simulate the nominal model (output error, from rest at u[0]).
  res.y_baseline_um = simulate(model, {}, data, o.io_delay_samples);
  res.baseline = errors_of(data, res.y_baseline_um, split);
  std::vector<double> sigmas;
  for (const auto& s : data) sigmas.push_back(estimate_noise_sigma(s.y_um));
  std::sort(sigmas.begin(), sigmas.end());
  const double sigma = std::max(sigmas[sigmas.size() / 2], 1e-9);
  res.noise_sigma_um = sigma;

  // 2. Locate: windows whose residual RMS exceeds the noise.
  bool any_window = false;
  for (size_t r = 0; r < data.size(); ++r) {
    const auto& s = data[r];
    const size_t w = std::max<size_t>(50, static_cast<size_t>(std::lround(o.window_s / s.sample_time_s)));
    MismatchWindow open;
    SquaredError open_err;
    bool is_open = false;
    size_t open_begin = 0;
    auto close = [&](size_t end) {
      open.t_end_s = s.t_s[end - 1] + s.sample_time_s;
      open.rms_um = std::sqrt(open_err.mse());
      open.regime = describe_regime(s, open_begin, end);
      res.mismatch.push_back(open);
      is_open = false;
    };
    for (size_t b = 0; b < s.u_V.size(); b += w) {
      const size_t e = std::min(b + w, s.u_V.size());
      if (e - b < w / 2) break;
      SquaredError err;
      for (size_t k = b; k < e; ++k) err.add(s.y_um[k] - res.y_baseline_um[r][k]);
      const double rms = std::sqrt(err.mse());
      res.window_centre_s.push_back(0.5 * (s.t_s[b] + s.t_s[e - 1]));
      res.window_rms_um.push_back(rms);
      res.window_recording.push_back(static_cast<int>(r));
      if (rms > o.window_flag_ratio * sigma) {
        any_window = true;
        if (!is_open) {
          open = MismatchWindow{static_cast<int>(r), s.t_s[b], 0.0, "", 0.0};
          open_err = {};
          open_begin = b;
          is_open = true;
        }
        open_err.sum += err.sum;
        open_err.n += err.n;
      } else if (is_open) {
        close(b);
      }
    }
    if (is_open) close(s.u_V.size());
  }

  res.fitted = res.baseline;
  res.y_fitted_um = res.y_baseline_um;
  if (!any_window && res.baseline.rmse_um <= o.none_ratio * sigma) {
    res.verdict = "none";
    res.explanation = std::string(physical_meaning(EffectKind::none)) + ": residual RMS " +
                      fmt("%.3g", res.baseline.rmse_um) + " um against an estimated sensor noise of " +
                      fmt("%.3g", sigma) + " um, and no window exceeds " + fmt("%.2g", o.window_flag_ratio) +
                      " times the noise";
    return res;
  }

  // 3. Diagnose: coarse grid per candidate (the evidence), then least squares on the leading ones.
  Problem problem(model, data, split, o.io_delay_samples);
  const double base_cost = problem.residual({}).squaredNorm();
  struct Start {
    double cost;
    Eigen::VectorXd z;
  };
  std::vector<std::vector<Start>> starts;
  for (EffectKind kind : kCandidateEffects) {
    CandidateResult c;
    c.effect.kind = kind;
    c.specs = parameter_specs(kind, data.front().sample_time_s, duration);
    add_data_starts(kind, c.specs, data);
    Coordinates coords{c.specs};
    std::vector<Start> grid{{0.0, Eigen::VectorXd::Zero(static_cast<Eigen::Index>(c.specs.size()))}};
    for (size_t i = 0; i < c.specs.size(); ++i) {
      std::vector<Start> next;
      for (const auto& g : grid)
        for (double v : c.specs[i].starts) {
          Start s = g;
          s.z(static_cast<Eigen::Index>(i)) = coords.to_z(i, std::clamp(v, c.specs[i].lower, c.specs[i].upper));
          next.push_back(s);
        }
      grid = std::move(next);
    }
    for (auto& g : grid) g.cost = problem.residual(make_effect(kind, coords, g.z)).squaredNorm();
    std::sort(grid.begin(), grid.end(), [](const Start& a, const Start& b) { return a.cost < b.cost; });
    c.evidence_r2 = std::max(0.0, 1.0 - grid.front().cost / base_cost);
    c.effect = make_effect(kind, coords, grid.front().z);
    res.candidates.push_back(c);
    grid.resize(std::min<size_t>(grid.size(), 2));
    starts.push_back(grid);
  }
  std::vector<size_t> order(res.candidates.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return res.candidates[a].evidence_r2 > res.candidates[b].evidence_r2; });
  for (size_t rank = 0; rank < order.size() && rank < static_cast<size_t>(o.candidates_to_fit); ++rank) {
    auto& c = res.candidates[order[rank]];
    Coordinates coords{c.specs};
    double best = INFINITY;
    for (const auto& s : starts[order[rank]]) {
      double cost = 0.0;
      const auto z = levenberg_marquardt(problem, c.effect.kind, coords, s.z, cost);
      if (cost < best) {
        best = cost;
        c.effect = make_effect(c.effect.kind, coords, z);
      }
    }
    c.fitted = true;
  }
  // 4. Choose by held-out error with a per-parameter penalty.
  for (auto& c : res.candidates) {
    if (!c.fitted) continue;
    c.errors = errors_of(data, simulate(model, c.effect, data, o.io_delay_samples), split);
    c.score = c.errors.rmse_validation_um * c.errors.rmse_validation_um *
              (1.0 + o.penalty_per_parameter * static_cast<double>(c.specs.size()));
  }
  std::stable_sort(res.candidates.begin(), res.candidates.end(), [](const CandidateResult& a, const CandidateResult& b) {
    if (a.fitted != b.fitted) return a.fitted;
    return a.fitted ? a.score < b.score : a.evidence_r2 > b.evidence_r2;
  });
  // When the held-out data cannot separate the two best (scores within the
  // tie margin), the one that also explains the fitting segment better wins.
  if (res.candidates.size() > 1 && res.candidates[1].fitted) {
    const auto& a = res.candidates[0];
    const auto& b = res.candidates[1];
    const double fit_a = a.errors.rmse_fit_um * a.errors.rmse_fit_um, fit_b = b.errors.rmse_fit_um * b.errors.rmse_fit_um;
    if (b.score <= a.score * (1.0 + o.tie_margin) && fit_b * (1.0 + o.tie_margin) < fit_a)
      std::swap(res.candidates[0], res.candidates[1]);
  }
  res.simulations = problem.simulations() + static_cast<int>(res.candidates.size());
  for (auto& c : res.candidates) {
    c.explanation = std::string(physical_meaning(c.effect.kind)) + ". Fitted " + parameters_text(c.effect, c.specs) +
                    (c.fitted ? "; validation RMSE " + fmt("%.3g", res.baseline.rmse_validation_um) + " -> " +
                                    fmt("%.3g", c.errors.rmse_validation_um) + " um"
                              : " (coarse grid only: not among the leading candidates)");
  }
  const auto& best = res.candidates.front();
  const double s2 = sigma * sigma;
  const double base_val = res.baseline.rmse_validation_um, base_fit = res.baseline.rmse_fit_um;
  // Judge on the held-out data when the mismatch reaches it; otherwise on the fit segment.
  const bool judge_val = base_val * base_val - s2 > 0.2 * s2;
  const double excess_base = judge_val ? base_val * base_val - s2 : base_fit * base_fit - s2;
  const double excess_best = judge_val ? best.errors.rmse_validation_um * best.errors.rmse_validation_um - s2
                                       : best.errors.rmse_fit_um * best.errors.rmse_fit_um - s2;
  const std::string runner_up =
      res.candidates.size() > 1 && res.candidates[1].fitted
          ? "; next best: " + std::string(to_string(res.candidates[1].effect.kind)) + " (validation RMSE " +
                fmt("%.3g", res.candidates[1].errors.rmse_validation_um) + " um)"
          : "";
  if (best.fitted && excess_base > 0.0 && excess_best <= o.explained_excess * excess_base) {
    res.verdict = std::string(to_string(best.effect.kind));
    res.chosen = best.effect.kind;
    res.effect = best.effect;
    res.fitted = best.errors;
    res.y_fitted_um = simulate(model, best.effect, data, o.io_delay_samples);
    res.explanation = "The nominal model leaves a residual of " + fmt("%.3g", res.baseline.rmse_um) + " um RMS against " +
                      fmt("%.3g", sigma) + " um of sensor noise. Best explanation: " + best.explanation +
                      " (noise " + fmt("%.3g", sigma) + " um)" + runner_up + ".";
  } else {
    res.verdict = "unexplained";
    res.explanation = "The nominal model leaves a residual of " + fmt("%.3g", res.baseline.rmse_um) + " um RMS against " +
                      fmt("%.3g", sigma) + " um of sensor noise, and no candidate explains it: the best (" +
                      std::string(to_string(best.effect.kind)) + ") leaves " +
                      fmt("%.0f", 100.0 * std::max(excess_best, 0.0) / std::max(excess_base, 1e-300)) +
                      "% of the excess residual variance" + runner_up + ".";
  }
  return res;
}

}  // namespace pvcgel::control::diagnosis
