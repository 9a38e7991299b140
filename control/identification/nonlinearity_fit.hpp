#pragma once
/// @file
/// Fitting the odd polynomial f from describing-function gains (paper eqs. (7)-(10)).

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

namespace pvcgel::control::identification {

/// Describing-function gains to fit: `d_k ~ N(A_k, B_k) = sum_i c_i h_i(A_k, B_k)`.
/// With d_k = (measured overall gain) / |G(j w_k)| this is the paper's eq. (10)
/// with every row divided by M_L(w_k), so each grid point counts alike.
struct DescribingFunctionData {
  Eigen::VectorXd amplitude_V, bias_V, gain;
};

/// One candidate degree.
struct PolynomialCandidate {
  int terms = 0;                    ///< n
  std::vector<double> c;            ///< c_1..c_n
  double residual_norm = 0.0;       ///< ||H c - d||
  double relative_residual = 0.0;   ///< ||H c - d|| / ||d||
  std::optional<double> turnover_V; ///< first x in (0, voltage_max] where f' = 0, if any
  [[nodiscard]] bool monotone() const noexcept { return !turnover_V.has_value(); }
};

/// Selection settings.
struct NonlinearityFitOptions {
  int max_terms = 4;           ///< fit n = 1..max_terms
  double tolerance = 0.10;     ///< accept residual <= (1 + tolerance) x the best admissible one
  double voltage_max_V = 1000.0;  ///< f must be strictly increasing on [0, this] to be admissible
  std::optional<int> forced_terms;  ///< take this n regardless of the rule
};

/// All candidates and the choice.
struct NonlinearityFit {
  std::vector<PolynomialCandidate> candidates;  ///< n = 1..max_terms
  int chosen_terms = 0;
  std::string rule;  ///< the rule applied, in words, with the numbers
  [[nodiscard]] const PolynomialCandidate& chosen() const { return candidates.at(static_cast<size_t>(chosen_terms - 1)); }
  [[nodiscard]] const PolynomialCandidate& candidate(int n) const { return candidates.at(static_cast<size_t>(n - 1)); }
};

/// Least squares (column-scaled QR) for one n.
/// @throws std::invalid_argument when there are fewer points than n or data are not finite.
PolynomialCandidate fit_odd_polynomial(int terms, const DescribingFunctionData& data, double voltage_max_V = 1000.0);

/// Fits n = 1..max_terms and chooses: the smallest n whose residual is within
/// `tolerance` of the best residual among the admissible candidates, where
/// admissible means f strictly increasing on [0, voltage_max_V] (the inverse
/// controller needs a monotone f over the whole voltage range).
/// @throws std::invalid_argument as fit_odd_polynomial, or when no candidate is admissible.
NonlinearityFit fit_nonlinearity(const DescribingFunctionData& data, const NonlinearityFitOptions& options = {});

}  // namespace pvcgel::control::identification
