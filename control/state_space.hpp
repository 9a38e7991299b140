#pragma once
/// @file
/// SISO state-space models and their discretisation (design time).

#include <Eigen/Core>
#include <complex>

#include "control/transfer_function.hpp"

namespace pvcgel::control {

/// SISO state space `x' = A x + B u, y = C x + D u` (continuous), or
/// `x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k]` (discrete). Design-time,
/// dynamically sized; LtiFilter is the allocation-free runtime form.
struct StateSpace {
  Eigen::MatrixXd A;
  Eigen::VectorXd B;
  Eigen::RowVectorXd C;
  double D = 0.0;

  /// Number of states.
  [[nodiscard]] int order() const noexcept { return static_cast<int>(A.rows()); }
};

/// Discrete-time transfer function in powers of z^-1:
/// `H(z) = (b0 + b1 z^-1 + ...) / (1 + a1 z^-1 + ...)`, `a[0]` = 1.
struct DiscreteTransferFunction {
  Eigen::VectorXd b;  ///< numerator, ascending powers of z^-1
  Eigen::VectorXd a;  ///< denominator, ascending powers of z^-1, a(0) = 1

  /// H(e^{j w Ts}).
  [[nodiscard]] std::complex<double> frequency_response(double omega_rad_s, double Ts_s) const;
  /// H(1), the steady-state gain.
  [[nodiscard]] double dc_gain() const;
  /// Roots in z of the denominator.
  [[nodiscard]] Eigen::VectorXcd poles() const;
  /// Roots in z of the numerator (without the trailing zeros at z = 0 that pure delays add).
  [[nodiscard]] Eigen::VectorXcd zeros() const;
  /// Number of leading zero numerator coefficients (whole-sample delay).
  [[nodiscard]] int delay_samples(double tol = 0.0) const;
  /// H * z^-n.
  [[nodiscard]] DiscreteTransferFunction delayed(int n) const;
  /// Series connection.
  friend DiscreteTransferFunction operator*(const DiscreteTransferFunction& x,
                                            const DiscreteTransferFunction& y);
};

/// Controllable canonical realisation of a proper continuous TF.
/// @throws ConfigError (key `key`) if g is improper.
StateSpace realize(const TransferFunction& g, const std::string& key = "model.G");
/// Observable canonical (direct form II transposed) realisation of a discrete TF.
StateSpace realize(const DiscreteTransferFunction& h);

/// Balances M in place by a diagonal similarity D^-1 M D of powers of two (Parlett and Reinsch, as LAPACK's
/// dgebal without its permutation): each state's row and column norms brought within a factor of two, which
/// changes no eigenvalue and, being powers of two, no bit of the matrix but its scale. Returns D's diagonal.
Eigen::VectorXd balance(Eigen::MatrixXd& M);

/// Exact zero-order-hold discretisation via the matrix exponential of [[A B];[0 0]] Ts.
StateSpace discretize_zoh(const StateSpace& continuous, double Ts_s);
/// Bilinear (Tustin) discretisation, no prewarping.
StateSpace discretize_tustin(const StateSpace& continuous, double Ts_s);
/// Transfer function of a discrete state-space model.
DiscreteTransferFunction to_transfer_function(const StateSpace& discrete);

}  // namespace pvcgel::control
