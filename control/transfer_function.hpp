#pragma once
/// @file
/// Continuous-time rational transfer functions, for design and configuration checks.

#include <Eigen/Core>
#include <complex>
#include <string>
#include <vector>

namespace pvcgel::control {

/// `G(s) = num(s) / den(s)`, coefficients in descending powers of s (the way the
/// paper and MATLAB write them). Design-time only; the loop runs LtiFilter.
class TransferFunction final {
 public:
  /// @throws ConfigError (naming `key`) on empty/non-finite coefficients or a zero leading denominator.
  TransferFunction(std::vector<double> num, std::vector<double> den,
                   const std::string& key = "model.G");

  /// Numerator, descending powers of s, leading zeros stripped.
  [[nodiscard]] const std::vector<double>& num() const noexcept { return num_; }
  /// Denominator, descending powers of s, leading zeros stripped.
  [[nodiscard]] const std::vector<double>& den() const noexcept { return den_; }
  /// Order of the denominator.
  [[nodiscard]] int order() const noexcept { return static_cast<int>(den_.size()) - 1; }
  /// deg(den) - deg(num); negative when improper.
  [[nodiscard]] int relative_degree() const noexcept {
    return static_cast<int>(den_.size()) - static_cast<int>(num_.size());
  }
  /// G(s).
  [[nodiscard]] std::complex<double> operator()(std::complex<double> s) const noexcept;
  /// G(0); infinite if den(0) = 0.
  [[nodiscard]] double dc_gain() const noexcept;
  /// Roots of den.
  [[nodiscard]] Eigen::VectorXcd poles() const;
  /// Roots of num.
  [[nodiscard]] Eigen::VectorXcd zeros() const;
  /// max -1 / Re(p) over the poles: the slowest mode's time constant (s) of a stable G; 0 without poles.
  [[nodiscard]] double slowest_time_constant_s() const;
  /// All poles strictly in the open left half plane.
  [[nodiscard]] bool is_stable() const;
  /// All zeros strictly in the open left half plane.
  [[nodiscard]] bool is_minimum_phase() const;

  /// Series connection a * b.
  friend TransferFunction operator*(const TransferFunction& a, const TransferFunction& b);
  /// 1 / G (improper when G is strictly proper).
  [[nodiscard]] TransferFunction inverse() const;

  /// Human-readable "(1.15 s + 1.03) / (s^2 + 17.11 s + 8.76)".
  [[nodiscard]] std::string to_string() const;

 private:
  std::vector<double> num_, den_;
};

/// Polynomial product (coefficient convolution), any order convention.
std::vector<double> polynomial_multiply(const std::vector<double>& a, const std::vector<double>& b);
/// Real coefficients, descending powers, of the monic polynomial with the given roots.
std::vector<double> polynomial_from_roots(const Eigen::VectorXcd& roots);
/// Roots of a polynomial given in descending powers.
Eigen::VectorXcd polynomial_roots(const std::vector<double>& descending);

}  // namespace pvcgel::control
