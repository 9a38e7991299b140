#include "control/polynomial_inverse.hpp"

#include <cmath>

#include "control/config_error.hpp"
#include "control/text_format.hpp"

namespace pvcgel::control {

PolynomialInverse::PolynomialInverse(OddPolynomial f, double lower_V, double upper_V,
                                     const std::string& key)
    : f_(std::move(f)), lower_V_(lower_V), upper_V_(upper_V) {
  if (!(lower_V >= 0.0 && upper_V > lower_V && upper_V <= 1000.0)) {
    throw ConfigError(key, format("inverse range [%g, %g] V must satisfy 0 <= lower < upper <= 1000", lower_V, upper_V));
  }
  if (const auto turn = f_.first_turnover(upper_V)) {
    if (*turn <= 0.0)
      throw ConfigError(key, format("f is not increasing at 0 V (c1 = %g): the inverse compensator needs f strictly "
                                    "increasing on [0, %g] V",
                                    f_.coefficient(1), upper_V));
    throw ConfigError(key, format("f is not strictly increasing on [0, %g] V: f'(x) = 0 at x = %.1f V (f turns over "
                                  "there). Usable range is 0..%.0f V: set the upper voltage limit below that or refit f",
                                  upper_V, *turn, std::floor(*turn)));
  }
  w_lower_ = f_(lower_V_);
  w_upper_ = f_(upper_V_);
}

double PolynomialInverse::operator()(double w) const noexcept {
  return (*this)(w, 0.5 * (lower_V_ + upper_V_));
}

double PolynomialInverse::operator()(double w, double hint) const noexcept {
  if (!(w > w_lower_)) return lower_V_;  // also catches NaN: fail towards the low voltage
  if (w >= w_upper_) return upper_V_;
  double lo = lower_V_, hi = upper_V_;
  double x = (hint > lo && hint < hi) ? hint : 0.5 * (lo + hi);
  const double w_tol = 1e-13 * std::abs(w) + 1e-300;
  for (int it = 0; it < 100; ++it) {
    double fx, dfx;
    f_.evaluate(x, fx, dfx);
    const double r = fx - w;
    if (std::abs(r) <= w_tol) return x;
    if (r < 0.0) lo = x; else hi = x;
    double next = x - r / dfx;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - x) <= 1e-13 * (1.0 + std::abs(x))) return next;
    x = next;
  }
  return x;
}

}  // namespace pvcgel::control
