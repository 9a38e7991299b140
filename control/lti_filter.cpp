#include "control/lti_filter.hpp"

#include <Eigen/Dense>
#include <limits>

#include "control/config_error.hpp"

namespace pvcgel::control {

LtiFilter::LtiFilter(const StateSpace& d) {
  const int n = d.order();
  if (n > kMaxOrder)
    throw ConfigError("filter", "order " + std::to_string(n) + " exceeds the supported " +
                                    std::to_string(kMaxOrder));
  A_ = d.A;
  B_ = d.B;
  C_ = d.C;
  D_ = d.D;
  x_ = Vector::Zero(n);
  steady_state_per_unit_input_ = Vector::Zero(n);
  dc_gain_ = D_;
  if (n > 0) {
    const Eigen::MatrixXd IminusA = Eigen::MatrixXd::Identity(n, n) - d.A;
    Eigen::FullPivLU<Eigen::MatrixXd> lu(IminusA);
    if (lu.isInvertible()) {
      steady_state_per_unit_input_ = lu.solve(d.B);
      dc_gain_ = C_.dot(steady_state_per_unit_input_) + D_;
    } else {
      dc_gain_ = std::numeric_limits<double>::quiet_NaN();
    }
  }
}

}  // namespace pvcgel::control
