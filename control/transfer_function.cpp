#include "control/transfer_function.hpp"

#include <algorithm>

#include <unsupported/Eigen/Polynomials>
#include <cmath>
#include <sstream>

#include "control/config_error.hpp"

namespace pvcgel::control {

namespace {
std::vector<double> strip_leading_zeros(std::vector<double> p) {
  size_t i = 0;
  while (i + 1 < p.size() && p[i] == 0.0) ++i;
  p.erase(p.begin(), p.begin() + static_cast<std::ptrdiff_t>(i));
  return p;
}
void check_finite(const std::vector<double>& p, const std::string& key, const char* what) {
  if (p.empty()) throw ConfigError(key, std::string(what) + " has no coefficients");
  for (double v : p)
    if (!std::isfinite(v)) throw ConfigError(key, std::string(what) + " has a non-finite coefficient");
}
}  // namespace

std::vector<double> polynomial_multiply(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.empty() || b.empty()) return {};
  std::vector<double> r(a.size() + b.size() - 1, 0.0);
  for (size_t i = 0; i < a.size(); ++i)
    for (size_t j = 0; j < b.size(); ++j) r[i + j] += a[i] * b[j];
  return r;
}

Eigen::VectorXcd polynomial_roots(const std::vector<double>& descending) {
  const auto p = strip_leading_zeros(descending);
  if (p.size() <= 1) return {};
  // Eigen wants ascending powers.
  Eigen::VectorXd asc(static_cast<Eigen::Index>(p.size()));
  for (size_t i = 0; i < p.size(); ++i) asc(static_cast<Eigen::Index>(i)) = p[p.size() - 1 - i];
  Eigen::PolynomialSolver<double, Eigen::Dynamic> solver(asc);
  return solver.roots();
}

std::vector<double> polynomial_from_roots(const Eigen::VectorXcd& roots) {
  Eigen::VectorXcd asc;
  Eigen::roots_to_monicPolynomial(roots, asc);
  std::vector<double> desc(static_cast<size_t>(asc.size()));
  for (Eigen::Index i = 0; i < asc.size(); ++i) desc[static_cast<size_t>(asc.size() - 1 - i)] = asc(i).real();
  return desc;
}

TransferFunction::TransferFunction(std::vector<double> num, std::vector<double> den,
                                   const std::string& key) {
  check_finite(num, key, "numerator");
  check_finite(den, key, "denominator");
  num_ = strip_leading_zeros(std::move(num));
  den_ = strip_leading_zeros(std::move(den));
  if (den_.size() == 1 && den_[0] == 0.0) throw ConfigError(key, "denominator is identically zero");
}

std::complex<double> TransferFunction::operator()(std::complex<double> s) const noexcept {
  std::complex<double> n = 0.0, d = 0.0;
  for (double c : num_) n = n * s + c;
  for (double c : den_) d = d * s + c;
  return n / d;
}

double TransferFunction::dc_gain() const noexcept { return num_.back() / den_.back(); }

Eigen::VectorXcd TransferFunction::poles() const { return polynomial_roots(den_); }
Eigen::VectorXcd TransferFunction::zeros() const { return polynomial_roots(num_); }
double TransferFunction::slowest_time_constant_s() const {
  double slowest = 0.0;
  for (const auto& p : poles()) slowest = std::max(slowest, -1.0 / p.real());
  return slowest;
}
bool TransferFunction::is_stable() const { return (poles().real().array() < 0.0).all(); }
bool TransferFunction::is_minimum_phase() const { return (zeros().real().array() < 0.0).all(); }

TransferFunction operator*(const TransferFunction& a, const TransferFunction& b) {
  return TransferFunction(polynomial_multiply(a.num_, b.num_), polynomial_multiply(a.den_, b.den_));
}

TransferFunction TransferFunction::inverse() const { return TransferFunction(den_, num_); }

std::string TransferFunction::to_string() const {
  auto poly = [](const std::vector<double>& p) {
    std::ostringstream os;
    const size_t n = p.size();
    bool first = true;
    for (size_t i = 0; i < n; ++i) {
      const double c = p[i];
      const size_t pw = n - 1 - i;
      if (c == 0.0 && n > 1) continue;
      if (!first) os << (c < 0 ? " - " : " + ");
      else if (c < 0) os << "-";
      const double a = std::abs(c);
      if (a != 1.0 || pw == 0) os << a << (pw ? " " : "");
      if (pw >= 1) os << "s";
      if (pw >= 2) os << "^" << pw;
      first = false;
    }
    return os.str();
  };
  return "(" + poly(num_) + ") / (" + poly(den_) + ")";
}

}  // namespace pvcgel::control
