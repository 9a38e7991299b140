#include "control/disturbance_observer.hpp"

#include <cmath>

#include "control/config_error.hpp"

namespace pvcgel::control {

DisturbanceObserver::DisturbanceObserver(const HammersteinModel& model, const DiscretePlantModel& plant,
                                         double lambda, int q_order) {
  if (!(lambda > 0.0 && std::isfinite(lambda)))
    throw ConfigError("controller.dob.lambda_s", "must be a positive number of seconds (paper: 0.1)");
  if (q_order < 1 || q_order > 4) throw ConfigError("controller.dob.q_order", "must be 1..4");
  std::vector<double> qden{1.0};
  for (int i = 0; i < q_order; ++i) qden = polynomial_multiply(qden, {lambda, 1.0});
  const TransferFunction Q({1.0}, qden, "controller.dob");
  qginv_ = Q * model.G.inverse();
  if (qginv_->relative_degree() < 0)
    throw ConfigError("controller.dob.q_order",
                      "Q(s) G^-1(s) = " + qginv_->to_string() + " is improper: Q's relative degree (" +
                          std::to_string(q_order) + ") must be at least G's (" +
                          std::to_string(model.G.relative_degree()) + ")");
  if (!qginv_->is_stable())
    throw ConfigError("model.G", "Q(s) G^-1(s) = " + qginv_->to_string() +
                                     " is unstable: G must be minimum phase");
  q_ = to_transfer_function(discretize_tustin(realize(Q, "controller.dob"), plant.Ts_s));
  from_output_ = LtiFilter(realize(q_ * plant.inverse));
  from_input_ = LtiFilter(realize(q_.delayed(plant.delay_samples)));
}

}  // namespace pvcgel::control
