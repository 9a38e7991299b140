#pragma once
/// @file
/// The paper's Hammerstein model and the controller's discrete view of it.

#include "control/odd_polynomial.hpp"
#include "control/state_space.hpp"
#include "control/transfer_function.hpp"

namespace pvcgel::control {

/// `y = G(s) [ f(x) ]`: odd polynomial f (x in V) followed by G(s) (output in um).
/// This is the `[model]` table of the configuration files.
struct HammersteinModel {
  OddPolynomial f;
  TransferFunction G;
};

/// The paper's model as identified (eq. (11) and Table II) for n = 1, 2 or 3.
HammersteinModel paper_model(int n);

/// G as the sampled loop sees it: `G_d(z) = z^-r B(z) / A(z)`, the exact ZOH
/// discretisation with `io_delay_samples` extra samples of I/O delay, plus its
/// causal inverse `A(z) / B(z)` that recovers the linear block's input r
/// samples late. Built once at configuration time.
struct DiscretePlantModel {
  DiscreteTransferFunction G_d;      ///< with every delay included
  DiscreteTransferFunction inverse;  ///< A / B: y[k] -> w[k - r]
  int delay_samples = 1;             ///< r
  double Ts_s = 1e-3;

  /// @throws ConfigError naming `key` if G is unstable, non-minimum phase, or
  ///         its sampled zeros leave the unit circle (the inverse would blow up).
  static DiscretePlantModel make(const TransferFunction& G, double Ts_s, int io_delay_samples,
                                 const std::string& key = "model.G");
};

}  // namespace pvcgel::control
