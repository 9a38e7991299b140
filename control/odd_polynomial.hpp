#pragma once
/// @file
/// The static nonlinearity of the Hammerstein model: an odd polynomial in volts.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

namespace pvcgel::control {

/// `w = f(x) = sum_i c_i x^(2i-1)` (paper eq. (2)); x in volts, w in the units
/// the linear block G(s) expects (G's output is in micrometres).
class OddPolynomial final {
 public:
  /// Largest number of coefficients supported on the hot path.
  static constexpr int kMaxTerms = 8;
  using Coefficients = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxTerms, 1>;

  /// @param c  c_1..c_n (n >= 1, n <= kMaxTerms, all finite)
  /// @param key  configuration key used in error messages
  /// @throws ConfigError if c is empty, too long or not finite
  explicit OddPolynomial(const std::vector<double>& c, const std::string& key = "model.poly");

  /// Number of terms n.
  [[nodiscard]] int terms() const noexcept { return static_cast<int>(c_.size()); }
  /// Coefficient c_i, i = 1..n.
  [[nodiscard]] double coefficient(int i) const noexcept { return c_(i - 1); }
  /// All coefficients as a vector.
  [[nodiscard]] std::vector<double> coefficients() const;

  /// f(x).
  [[nodiscard]] double operator()(double x_V) const noexcept {
    // Horner in x^2, f = x p(x^2): evaluate's f without its derivative (inline: the diagnosis's hot loop).
    const double x2 = x_V * x_V;
    double p = 0.0;
    for (Eigen::Index i = c_.size() - 1; i >= 0; --i) p = p * x2 + c_(i);
    return x_V * p;
  }
  /// f'(x).
  [[nodiscard]] double derivative(double x_V) const noexcept;
  /// f(x) and f'(x) in one Horner pass.
  void evaluate(double x_V, double& f, double& df) const noexcept;

  /// First x in (0, x_max_V] where f' reaches zero, i.e. where f stops being
  /// strictly increasing; empty when f is strictly increasing on [0, x_max_V].
  [[nodiscard]] std::optional<double> first_turnover(double x_max_V) const;

  /// Fundamental-harmonic gain of f for x = B + A sin(wt): b1 / A, where b1 is
  /// the sin coefficient of f's output (paper eq. (5)-(7), generalised to any n).
  /// The cos coefficient is zero for a static odd polynomial.
  [[nodiscard]] double describing_function(double amplitude_V, double bias_V) const;

  /// Row of the describing-function regression matrix H (paper eq. (8)-(10)):
  /// element i is the contribution of c_{i+1} to b1 / A.
  [[nodiscard]] static Eigen::VectorXd describing_function_basis(int terms, double amplitude_V,
                                                                double bias_V);

 private:
  Coefficients c_;
};

}  // namespace pvcgel::control
