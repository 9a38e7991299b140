#pragma once
// Small helpers shared by the identification tests.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <complex>
#include <utility>
#include <vector>

#include "control/transfer_function.hpp"

namespace pvcgel::test {

/// Roots sorted by real part, so fitted and true roots compare pairwise.
inline std::vector<std::complex<double>> sorted_roots(const Eigen::VectorXcd& r) {
  std::vector<std::complex<double>> v(r.data(), r.data() + r.size());
  std::sort(v.begin(), v.end(), [](auto a, auto b) { return a.real() < b.real(); });
  return v;
}

/// Exact frequency response of G at the given frequencies (Hz): (omega_rad_s, G(j omega)).
inline std::pair<Eigen::VectorXd, Eigen::VectorXcd> exact_response(const control::TransferFunction& G,
                                                                  const std::vector<double>& f_Hz) {
  const auto n = static_cast<Eigen::Index>(f_Hz.size());
  Eigen::VectorXd w(n);
  Eigen::VectorXcd H(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    w(k) = 2 * M_PI * f_Hz[static_cast<size_t>(k)];
    H(k) = G({0.0, w(k)});
  }
  return {w, H};
}

}  // namespace pvcgel::test
