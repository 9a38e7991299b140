#include "control/identification/frequency_response.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

namespace pvcgel::control::identification {

namespace {

constexpr double kPi = std::numbers::pi;

/// Regressors [1, (trend), cos(k w tau), sin(k w tau)] for samples [b, e), tau = t - t_ref.
/// Harmonics by complex recursion: one sin/cos pair per sample, not 2H.
Eigen::MatrixXd harmonic_basis(const std::vector<double>& t, size_t b, size_t e, double t_ref, double half_span_s,
                               double omega, int harmonics, bool trend) {
  const auto rows = static_cast<Eigen::Index>(e - b);
  const int lead = trend ? 2 : 1;
  Eigen::MatrixXd X(rows, lead + 2 * harmonics);
  for (Eigen::Index r = 0; r < rows; ++r) {
    const double tau = t[b + static_cast<size_t>(r)] - t_ref;
    X(r, 0) = 1.0;
    if (trend) X(r, 1) = tau / half_span_s;
    const std::complex<double> e1 = std::polar(1.0, omega * tau);
    std::complex<double> ek = e1;
    for (int k = 0; k < harmonics; ++k) {
      X(r, lead + 2 * k) = ek.real();
      X(r, lead + 2 * k + 1) = ek.imag();
      ek *= e1;
    }
  }
  return X;
}

/// Phasor of harmonic k (0-based) from cos/sin coefficients: x = Re{X e^{j w t}}.
std::complex<double> phasor(const Eigen::VectorXd& coef, int lead, int k) {
  return {coef(lead + 2 * k), -coef(lead + 2 * k + 1)};
}

}  // namespace

double FrequencyResponsePoint::omega_rad_s() const noexcept { return 2.0 * kPi * frequency_Hz; }

namespace {

/// The frequency (rad/s) from upward crossings of the mid level over [b, e), with hysteresis (noise near
/// the mid level cannot double count); NaN without two crossings or with a flat signal.
double crossing_frequency(const std::vector<double>& t, const std::vector<double>& u, size_t b, size_t e) {
  const auto [mn, mx] = std::minmax_element(u.begin() + static_cast<long>(b), u.begin() + static_cast<long>(e));
  const double mid = 0.5 * (*mn + *mx), band = 0.25 * (*mx - *mn);
  if (!(band > 0.0)) return NAN;
  std::vector<double> crossings;
  bool armed = false;
  for (size_t k = b + 1; k < e; ++k) {
    if (u[k] < mid - band) armed = true;
    if (armed && u[k - 1] < mid && u[k] >= mid) {
      const double frac = (mid - u[k - 1]) / (u[k] - u[k - 1]);
      crossings.push_back(t[k - 1] + frac * (t[k] - t[k - 1]));
      armed = false;
    }
  }
  if (crossings.size() < 2) return NAN;
  return 2.0 * kPi * static_cast<double>(crossings.size() - 1) / (crossings.back() - crossings.front());
}

/// B + a cos(w tau) + b sin(w tau) fitted to uu: linear at the coarse `omega`, then Gauss-Newton on
/// (B, a, b, w). Returns (B, a, b, w).
Eigen::Vector4d fit_sine(const Eigen::VectorXd& tau, const Eigen::VectorXd& uu, double omega) {
  const auto n = tau.size();
  Eigen::Vector4d p;
  Eigen::MatrixXd X(n, 3);
  X.col(0).setOnes();
  X.col(1) = (omega * tau).array().cos();
  X.col(2) = (omega * tau).array().sin();
  p.head<3>() = X.colPivHouseholderQr().solve(uu);
  p(3) = omega;
  Eigen::MatrixXd J(n, 4);
  Eigen::VectorXd r(n);
  for (int it = 0; it < 20; ++it) {
    const Eigen::ArrayXd c = (p(3) * tau).array().cos(), sn = (p(3) * tau).array().sin();
    r = uu.array() - (p(0) + p(1) * c + p(2) * sn);
    J.col(0).setOnes();
    J.col(1) = c.matrix();
    J.col(2) = sn.matrix();
    J.col(3) = (tau.array() * (-p(1) * sn + p(2) * c)).matrix();
    const Eigen::Vector4d d = J.colPivHouseholderQr().solve(r);
    p += d;
    if (std::abs(d(3)) <= 1e-13 * std::abs(p(3))) break;
  }
  return p;
}

}  // namespace

SineEstimate estimate_sine(const std::vector<double>& t, const std::vector<double>& u, size_t b, size_t e) {
  SineEstimate s;
  if (e <= b + 8 || e > u.size() || e > t.size()) return s;
  const double omega = crossing_frequency(t, u, b, e);
  if (std::isnan(omega)) return s;
  const double t_c = 0.5 * (t[b] + t[e - 1]);
  const auto n = static_cast<Eigen::Index>(e - b);
  Eigen::VectorXd uu(n), tau(n);
  for (Eigen::Index r = 0; r < n; ++r) {
    uu(r) = u[b + static_cast<size_t>(r)];
    tau(r) = t[b + static_cast<size_t>(r)] - t_c;
  }
  const Eigen::Vector4d p = fit_sine(tau, uu, omega);
  const Eigen::ArrayXd c = (p(3) * tau).array().cos(), sn = (p(3) * tau).array().sin();
  const Eigen::VectorXd r = uu.array() - (p(0) + p(1) * c + p(2) * sn);
  s.bias_V = p(0);
  s.amplitude_V = std::hypot(p(1), p(2));
  s.frequency_Hz = std::abs(p(3)) / (2.0 * kPi);
  // a cos + b sin = A sin(w tau + phi), phi = atan2(a, b); referred to t[b].
  s.phase_rad = std::remainder(std::atan2(p(1), p(2)) - p(3) * (t_c - t[b]), 2.0 * kPi);
  s.residual_rms_V = std::sqrt(r.squaredNorm() / static_cast<double>(n));
  s.found = std::isfinite(s.frequency_Hz) && s.frequency_Hz > 0.0;
  return s;
}

namespace {

/// Why the samples cannot be analysed at all (different lengths, too few, not finite), else empty.
std::string record_problem(const std::vector<double>& t, const std::vector<double>& u, const std::vector<double>& y) {
  const size_t n = t.size();
  if (u.size() != n || y.size() != n) return "t_s, u_V and y_um have different lengths";
  if (n < 20) return "fewer than 20 samples";
  for (size_t k = 0; k < n; ++k)
    if (!std::isfinite(t[k]) || !std::isfinite(u[k]) || !std::isfinite(y[k]))
      return "non-finite sample at row " + std::to_string(k);
  return {};
}

/// Clipping and distortion: the input must be the sinusoid the describing function assumes. Why it is not
/// (over the analysed samples from `start`), else empty.
std::string input_problem(const std::vector<double>& u, size_t start, const SineEstimate& s, double distortion,
                          const ExtractionOptions& o) {
  std::ostringstream os;
  const auto [mn, mx] = std::minmax_element(u.begin() + static_cast<long>(start), u.end());
  const double tol = 1e-3 * s.amplitude_V;
  if (distortion > o.max_input_distortion) {
    os << "u_V is not a clean sine (fit residual " << 100.0 * distortion << "% of A, limit "
       << 100.0 * o.max_input_distortion << "%)";
    if (*mx >= o.voltage_max_V - tol) os << ": clipped at " << *mx << " V (saturated at the upper limit)";
    else if (*mn <= o.voltage_min_V + tol) os << ": clipped at " << *mn << " V (saturated at the lower limit)";
  } else if (s.bias_V + s.amplitude_V > o.voltage_max_V + tol || s.bias_V - s.amplitude_V < o.voltage_min_V - tol) {
    os << "the sine spans " << s.bias_V - s.amplitude_V << " .. " << s.bias_V + s.amplitude_V << " V, outside "
       << o.voltage_min_V << " .. " << o.voltage_max_V << " V";
  }
  return os.str();
}

/// The analysed window's samples and the fit's reference time and half span.
struct Window {
  size_t start = 0, end = 0;
  double t_ref_s = 0.0, half_span_s = 0.0;
  Eigen::MatrixXd rhs;  ///< columns u, y over [start, end)
};

/// Per-period estimates of the response: their spread is the uncertainty (noise, drift, hysteresis and
/// anything else that is not a stationary response shows up there). 0 with fewer than two periods.
double per_period_sigma(const std::vector<double>& t, const Window& w, double period_samples, int periods,
                        double omega, int harmonics) {
  std::vector<std::complex<double>> per;
  for (int p = 0; p < periods; ++p) {
    const size_t b = w.start + static_cast<size_t>(std::llround(p * period_samples));
    const size_t e = std::min(w.end, w.start + static_cast<size_t>(std::llround((p + 1) * period_samples)));
    if (e <= b + 4) continue;
    const Eigen::MatrixXd Xp = harmonic_basis(t, b, e, w.t_ref_s, w.half_span_s, omega, harmonics, false);
    const Eigen::MatrixXd cp = Xp.householderQr().solve(
        w.rhs.middleRows(static_cast<Eigen::Index>(b - w.start), static_cast<Eigen::Index>(e - b)));
    per.push_back(phasor(cp.col(1), 1, 0) / phasor(cp.col(0), 1, 0));
  }
  if (per.size() < 2) return 0.0;
  std::complex<double> mean{0.0, 0.0};
  for (auto h : per) mean += h;
  mean /= static_cast<double>(per.size());
  double ss = 0.0;
  for (auto h : per) ss += std::norm(h - mean);
  const double m = static_cast<double>(per.size());
  return std::sqrt(ss / (m - 1.0)) / std::sqrt(m);
}

/// The response, DC, drift and harmonics by the lock-in fit over the window, and their per-period spread.
void fit_harmonics(FrequencyResponsePoint& P, const std::vector<double>& t, const std::vector<double>& u,
                   const std::vector<double>& y, size_t start, double Ts, const ExtractionOptions& o) {
  const size_t n = t.size();
  // Harmonics up to 90% of Nyquist only.
  const int H = std::max(1, std::min(o.harmonics, static_cast<int>(0.45 / (P.frequency_Hz * Ts))));
  const double omega = 2.0 * kPi * P.frequency_Hz;
  Window w{.start = start, .end = n, .t_ref_s = 0.5 * (t[start] + t[n - 1]),
           .half_span_s = std::max(0.5 * (t[n - 1] - t[start]), Ts), .rhs = Eigen::MatrixXd(static_cast<Eigen::Index>(n - start), 2)};
  for (size_t k = start; k < n; ++k) {
    w.rhs(static_cast<Eigen::Index>(k - start), 0) = u[k];
    w.rhs(static_cast<Eigen::Index>(k - start), 1) = y[k];
  }
  const Eigen::MatrixXd X = harmonic_basis(t, start, n, w.t_ref_s, w.half_span_s, omega, H, true);
  const Eigen::MatrixXd coef = X.householderQr().solve(w.rhs);
  P.response = phasor(coef.col(1), 2, 0) / phasor(coef.col(0), 2, 0);
  P.dc_um = coef(0, 1);
  P.drift_um_per_s = coef(1, 1) / w.half_span_s;
  for (int k = 0; k < H; ++k) P.harmonic_um.push_back(std::abs(phasor(coef.col(1), 2, k)));
  P.response_sigma = per_period_sigma(t, w, 1.0 / (P.frequency_Hz * Ts), P.periods, omega, H);
}

}  // namespace

FrequencyResponsePoint extract_frequency_response(const std::vector<double>& t, const std::vector<double>& u,
                                                  const std::vector<double>& y, const ExtractionOptions& o,
                                                  std::string source) {
  FrequencyResponsePoint P;
  P.source = std::move(source);
  auto flag = [&](const std::string& why) {
    P.valid = false;
    P.problem = why;
    return P;
  };
  if (auto why = record_problem(t, u, y); !why.empty()) return flag(why);
  const size_t n = t.size();
  const double Ts = (t.back() - t.front()) / static_cast<double>(n - 1);
  size_t begin = 0;
  while (begin < n && t[begin] - t.front() < o.settle_s - 0.5 * Ts) ++begin;
  std::ostringstream os;
  if (n - begin < 20) {
    os << "the record (" << t.back() - t.front() << " s) is not longer than the settling time (" << o.settle_s
       << " s): nothing to analyse";
    return flag(os.str());
  }
  const SineEstimate s = estimate_sine(t, u, begin, n);
  if (!s.found) {
    os << "u_V does not oscillate after the " << o.settle_s << " s settling time (fewer than 2 crossings): too few periods";
    return flag(os.str());
  }
  P.amplitude_V = s.amplitude_V;
  P.bias_V = s.bias_V;
  P.frequency_Hz = s.frequency_Hz;
  P.input_distortion = s.residual_rms_V / s.amplitude_V;

  const double period_samples = 1.0 / (s.frequency_Hz * Ts);
  P.periods = static_cast<int>(std::floor(static_cast<double>(n - begin) / period_samples + 1e-6));
  if (P.periods < o.min_periods) {
    os << "only " << P.periods << " whole period(s) of " << s.frequency_Hz << " Hz after the " << o.settle_s
       << " s settling time (need at least " << o.min_periods << ")";
    return flag(os.str());
  }
  const auto L = static_cast<size_t>(std::llround(P.periods * period_samples));
  const size_t start = n - std::min(L, n - begin);
  P.window_start_s = t[start] - t.front();
  P.window_end_s = t.back() - t.front() + Ts;
  if (auto why = input_problem(u, start, s, P.input_distortion, o); !why.empty()) return flag(why);

  fit_harmonics(P, t, u, y, start, Ts, o);
  if (!std::isfinite(std::abs(P.response))) return flag("no finite response (zero input amplitude?)");
  P.valid = true;
  return P;
}

}  // namespace pvcgel::control::identification
