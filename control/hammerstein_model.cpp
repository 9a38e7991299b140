#include "control/hammerstein_model.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "control/config_error.hpp"

namespace pvcgel::control {

HammersteinModel paper_model(int n) {
  const TransferFunction G({1.15, 1.03}, {1.0, 17.11, 8.76});
  switch (n) {
    case 1: return {OddPolynomial({1.3664}), G};
    case 2: return {OddPolynomial({0.1270, 1.3057e-5}), G};
    case 3: return {OddPolynomial({0.0721, 2.1307e-5, -1.7231e-11}), G};
    default: throw ConfigError("model.poly", "the paper identified n = 1, 2, 3 only");
  }
}

DiscretePlantModel DiscretePlantModel::make(const TransferFunction& G, double Ts, int io_delay,
                                            const std::string& key) {
  if (!(Ts > 0.0 && Ts <= 0.1)) throw ConfigError("loop.period_s", "must be in (0, 0.1] s");
  if (io_delay < 0 || io_delay > 8)
    throw ConfigError("model.io_delay_samples", "must be 0..8 samples");
  if (!G.is_stable()) throw ConfigError(key, "G(s) = " + G.to_string() + " is unstable");
  if (G.relative_degree() < 0) throw ConfigError(key, "G(s) = " + G.to_string() + " is improper");
  if (!G.is_minimum_phase())
    throw ConfigError(key, "G(s) = " + G.to_string() +
                               " has a right-half-plane zero (non-minimum phase): its inverse, needed by "
                               "the disturbance observer Q G^-1 and the feedforward, would be unstable");
  DiscretePlantModel m;
  m.Ts_s = Ts;
  const auto gd = to_transfer_function(discretize_zoh(realize(G, key), Ts));
  const int inherent = gd.delay_samples(1e-12);
  m.delay_samples = inherent + io_delay;
  m.G_d = gd.delayed(io_delay);
  if (m.delay_samples < 1)
    throw ConfigError("model.io_delay_samples",
                      "G is biproper, so at least one sample of I/O delay must be modelled (the "
                      "disturbance observer would otherwise form an algebraic loop)");
  // B(z): the numerator without its leading delay.
  const Eigen::VectorXd B = gd.b.tail(gd.b.size() - inherent);
  const auto zeros = DiscreteTransferFunction{B, Eigen::VectorXd::Ones(1)}.zeros();
  for (const auto& z : zeros) {
    if (std::abs(z) >= 1.0 - 1e-9) {
      std::ostringstream os;
      os << "sampled G has a zero at z = " << z
         << " on or outside the unit circle (a sampling zero: G's relative degree is "
         << G.relative_degree() << "); the exact discrete inverse would be unstable at this sample time";
      throw ConfigError(key, os.str());
    }
  }
  m.inverse = DiscreteTransferFunction{gd.a / B(0), B / B(0)};
  return m;
}

}  // namespace pvcgel::control
