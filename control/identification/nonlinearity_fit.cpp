#include "control/identification/nonlinearity_fit.hpp"
#include "control/text_format.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "control/odd_polynomial.hpp"

namespace pvcgel::control::identification {

PolynomialCandidate fit_odd_polynomial(int n, const DescribingFunctionData& d, double vmax) {
  const Eigen::Index K = d.gain.size();
  if (n < 1 || n > OddPolynomial::kMaxTerms) throw std::invalid_argument("polynomial terms must be 1..8");
  if (d.amplitude_V.size() != K || d.bias_V.size() != K) throw std::invalid_argument("describing-function data sizes differ");
  if (K < n)
    throw std::invalid_argument("only " + std::to_string(K) + " valid grid points for " + std::to_string(n) +
                                " polynomial coefficients");
  if (!d.gain.allFinite() || !d.amplitude_V.allFinite() || !d.bias_V.allFinite())
    throw std::invalid_argument("describing-function data are not finite");
  Eigen::MatrixXd H(K, n);
  for (Eigen::Index k = 0; k < K; ++k)
    H.row(k) = OddPolynomial::describing_function_basis(n, d.amplitude_V(k), d.bias_V(k)).transpose();
  // Columns span ~x^0..x^(2n-2) (1 .. 1e14 at 500 V): scale them to unit norm first.
  const Eigen::VectorXd scale = H.colwise().norm().transpose();
  const Eigen::MatrixXd Hs = H * scale.cwiseInverse().asDiagonal();
  const Eigen::VectorXd cs = Hs.colPivHouseholderQr().solve(d.gain);
  const Eigen::VectorXd c = cs.cwiseQuotient(scale);
  PolynomialCandidate out;
  out.terms = n;
  out.c.assign(c.data(), c.data() + c.size());
  out.residual_norm = (H * c - d.gain).norm();
  out.relative_residual = out.residual_norm / d.gain.norm();
  out.turnover_V = OddPolynomial(out.c, "ident.poly").first_turnover(vmax);
  return out;
}

NonlinearityFit fit_nonlinearity(const DescribingFunctionData& d, const NonlinearityFitOptions& o) {
  NonlinearityFit fit;
  const int max_n = std::min<int>(o.max_terms, static_cast<int>(d.gain.size()));
  if (max_n < 1) throw std::invalid_argument("no valid grid points to fit the nonlinearity");
  for (int n = 1; n <= max_n; ++n) fit.candidates.push_back(fit_odd_polynomial(n, d, o.voltage_max_V));
  std::ostringstream os;
  if (o.forced_terms) {
    if (*o.forced_terms < 1 || *o.forced_terms > max_n)
      throw std::invalid_argument("requested n = " + std::to_string(*o.forced_terms) + " is outside 1.." +
                                  std::to_string(max_n));
    fit.chosen_terms = *o.forced_terms;
    os << "n = " << fit.chosen_terms << " as requested";
    if (!fit.chosen().monotone())
      os << " (WARNING: f turns over at " << *fit.chosen().turnover_V << " V, below " << o.voltage_max_V << " V)";
    fit.rule = os.str();
    return fit;
  }
  double best = INFINITY;
  int best_n = 0;
  for (const auto& c : fit.candidates)
    if (c.monotone() && c.residual_norm < best) {
      best = c.residual_norm;
      best_n = c.terms;
    }
  if (best_n == 0)
    throw std::invalid_argument("no polynomial degree 1.." + std::to_string(max_n) +
                                format(" gives an f that is strictly increasing on [0, %g] V", o.voltage_max_V));
  for (const auto& c : fit.candidates)
    if (c.monotone() && c.residual_norm <= (1.0 + o.tolerance) * best) {
      fit.chosen_terms = c.terms;
      break;
    }
  os << "smallest n whose residual is within " << 100.0 * o.tolerance << "% of the best admissible one (n = "
     << best_n << ", " << best << "); admissible: f strictly increasing on [0, " << o.voltage_max_V << "] V";
  for (const auto& c : fit.candidates)
    if (!c.monotone()) os << "; n = " << c.terms << " excluded: f turns over at " << *c.turnover_V << " V";
  fit.rule = os.str();
  return fit;
}

}  // namespace pvcgel::control::identification
