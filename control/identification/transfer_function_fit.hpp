#pragma once
/// @file
/// Fitting a rational G(s) to a measured complex frequency response (what
/// MATLAB's tfest did for the paper's eq. (11)).

#include <Eigen/Core>
#include <complex>
#include <string>

#include "control/transfer_function.hpp"

namespace pvcgel::control::identification {

/// Model orders and iteration limits.
struct TransferFunctionFitOptions {
  int numerator_order = 1;    ///< deg num (the paper: 1)
  int denominator_order = 2;  ///< deg den (the paper: 2); den is monic
  int sk_iterations = 30;     ///< Sanathanan-Koerner iterations at most
  int lm_max_evaluations = 4000;
};

/// The fitted G(s) and what a user needs to judge it.
struct TransferFunctionFit {
  TransferFunction G;
  double fit_percent = 0.0;     ///< 100 (1 - ||H - G|| / ||H - mean(H)||), the tfest measure
  double sk_fit_percent = 0.0;  ///< the same after the linear (SK) stage only
  int sk_iterations = 0;
  int lm_iterations = 0;
  std::string lm_status;        ///< Eigen's LevenbergMarquardt termination reason
  double max_relative_error = 0.0;  ///< max |G - H| / |H| over the points
  Eigen::VectorXcd poles, zeros;
  bool stable = false;          ///< all poles in the open left half plane
  bool minimum_phase = false;   ///< all zeros in the open left half plane

  /// Empty when G is usable for control (stable and minimum phase); otherwise
  /// a message that says why not (the inverse and the DOB need both).
  [[nodiscard]] std::string control_problem() const;
};

/// Fits `G(jw) ~ response` with relative (1/|H|) weighting of the complex
/// error, so every frequency counts alike: a Levy / Sanathanan-Koerner linear
/// iteration (frequency scaled by the geometric mean of omega for conditioning)
/// initialises a Levenberg-Marquardt refinement of the same complex error.
/// @throws std::invalid_argument on sizes, non-finite data or too few points
///         (need 2 points >= parameters, i.e. 2K >= nb + na + 1).
TransferFunctionFit fit_transfer_function(const Eigen::VectorXd& omega_rad_s, const Eigen::VectorXcd& response,
                                          const TransferFunctionFitOptions& options = {});

}  // namespace pvcgel::control::identification
