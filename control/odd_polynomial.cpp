#include "control/odd_polynomial.hpp"

#include <unsupported/Eigen/Polynomials>
#include <cmath>
#include <limits>

#include "control/config_error.hpp"

namespace pvcgel::control {

OddPolynomial::OddPolynomial(const std::vector<double>& c, const std::string& key) {
  if (c.empty()) throw ConfigError(key, "needs at least one coefficient (c1)");
  if (c.size() > static_cast<size_t>(kMaxTerms))
    throw ConfigError(key, "at most " + std::to_string(kMaxTerms) + " coefficients are supported, got " +
                               std::to_string(c.size()));
  c_.resize(static_cast<Eigen::Index>(c.size()));
  for (size_t i = 0; i < c.size(); ++i) {
    if (!std::isfinite(c[i]))
      throw ConfigError(key, "coefficient c" + std::to_string(i + 1) + " is not a finite number");
    c_(static_cast<Eigen::Index>(i)) = c[i];
  }
}

std::vector<double> OddPolynomial::coefficients() const { return {c_.data(), c_.data() + c_.size()}; }

void OddPolynomial::evaluate(double x, double& f, double& df) const noexcept {
  // Horner in x^2: f = x * p(x^2), f' = p(x^2) + 2 x^2 p'(x^2).
  const double x2 = x * x;
  double p = 0.0, dp = 0.0;
  for (Eigen::Index i = c_.size() - 1; i >= 0; --i) {
    dp = dp * x2 + p;
    p = p * x2 + c_(i);
  }
  f = x * p;
  df = p + 2.0 * x2 * dp;
}

double OddPolynomial::derivative(double x) const noexcept {
  double f, df;
  evaluate(x, f, df);
  return df;
}

std::optional<double> OddPolynomial::first_turnover(double x_max) const {
  // f'(x) = sum (2i-1) c_i z^(i-1) with z = x^2: find its smallest positive root.
  const Eigen::Index n = c_.size();
  if (c_(0) < 0.0) return 0.0;
  if (n == 1) {
    if (c_(0) == 0.0) return 0.0;
    return std::nullopt;
  }
  Eigen::VectorXd q(n);
  for (Eigen::Index i = 0; i < n; ++i) q(i) = static_cast<double>(2 * i + 1) * c_(i);
  Eigen::Index deg = n - 1;
  while (deg > 0 && q(deg) == 0.0) --deg;
  double best = std::numeric_limits<double>::infinity();
  if (deg > 0) {
    Eigen::PolynomialSolver<double, Eigen::Dynamic> solver(q.head(deg + 1));
    for (const auto& root : solver.roots()) {
      const double z = root.real();
      if (std::abs(root.imag()) <= 1e-9 * std::max(1.0, std::abs(z)) && z > 0.0) {
        const double x = std::sqrt(z);
        // A double root touches zero without a sign change; only a sign change turns f over.
        if (derivative(x * (1.0 + 1e-6)) <= 0.0 && x < best) best = x;
      }
    }
  }
  if (c_(0) == 0.0 && derivative(1e-3 * x_max) <= 0.0) return 0.0;
  if (best <= x_max) return best;
  return std::nullopt;
}

namespace {
// (1/pi) * integral over one period of sin^(k+1)(t) dt, for odd k: 2 * C(k+1, (k+1)/2) / 2^(k+1).
double sin_power_mean(int k) {
  const int m = k + 1;
  double binom = 1.0;
  for (int j = 1; j <= m / 2; ++j) binom = binom * (m / 2 + j) / j;
  return 2.0 * binom / std::ldexp(1.0, m);
}
}  // namespace

Eigen::VectorXd OddPolynomial::describing_function_basis(int terms, double A, double B) {
  // Fundamental sin coefficient of (B + A sin t)^m is sum over odd k of
  // C(m,k) B^(m-k) A^k (1/pi) int sin^(k+1); dividing by A gives the gain.
  Eigen::VectorXd h(terms);
  for (int i = 0; i < terms; ++i) {
    const int m = 2 * i + 1;
    double sum = 0.0, binom = 1.0;  // binom = C(m, k)
    for (int k = 0; k <= m; ++k) {
      if (k > 0) binom = binom * (m - k + 1) / k;
      if (k % 2 == 1) sum += binom * std::pow(B, m - k) * std::pow(A, k - 1) * sin_power_mean(k);
    }
    h(i) = sum;
  }
  return h;
}

double OddPolynomial::describing_function(double A, double B) const {
  return describing_function_basis(terms(), A, B).dot(c_);
}

}  // namespace pvcgel::control
