#pragma once
/// @file
/// The controller's inverse compensator f^-1 (paper Fig. 4).

#include "control/odd_polynomial.hpp"

namespace pvcgel::control {

/// Solves f(x) = w for x on [lower_V, upper_V], where f is strictly increasing
/// there (checked at construction). Bracketed Newton: a Newton step that would
/// leave the bracket becomes a bisection step, so it never diverges; requests
/// beyond f(lower) or f(upper) return the bound (the output stage clamps there
/// anyway). Real-time safe: no allocation, no exceptions.
class PolynomialInverse final {
 public:
  /// @param f  the identified nonlinearity
  /// @param lower_V, upper_V  the voltage range the inverse must cover (within 0..1000 V)
  /// @param key  configuration key used in error messages
  /// @throws ConfigError if f is not strictly increasing on [0, upper_V]; the
  ///         message says where f turns over and which range would be usable.
  PolynomialInverse(OddPolynomial f, double lower_V, double upper_V,
                    const std::string& key = "model.poly");

  /// x with f(x) = w, relative accuracy 1e-12 in w or 1e-12 V in x.
  /// @param hint_V  a starting guess (e.g. the previous cycle's output); any value works.
  [[nodiscard]] double operator()(double w, double hint_V) const noexcept;
  /// Same, starting from the middle of the range.
  [[nodiscard]] double operator()(double w) const noexcept;

  /// The polynomial being inverted.
  [[nodiscard]] const OddPolynomial& forward() const noexcept { return f_; }
  /// Lower end of the covered range, V.
  [[nodiscard]] double lower_V() const noexcept { return lower_V_; }
  /// Upper end of the covered range, V.
  [[nodiscard]] double upper_V() const noexcept { return upper_V_; }

 private:
  OddPolynomial f_;
  double lower_V_, upper_V_;
  double w_lower_, w_upper_;
};

}  // namespace pvcgel::control
