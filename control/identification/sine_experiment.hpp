#pragma once
/// @file
/// Running sine experiments on the simulated rig, and simulating an identified
/// Hammerstein model on a recorded input (time-domain validation).

#include <vector>

#include "control/hammerstein_model.hpp"
#include "control/identification/excitation_plan.hpp"
#include "control/simulated_rig.hpp"

namespace pvcgel::control::identification {

/// Sampled input/output of one experiment in the daemon's convention: row k
/// holds y measured at t_k and the u then applied and held until t_{k+1}.
struct SineRecord {
  SinePoint point;            ///< what was commanded (unknown for recordings: NaN fields)
  double sample_time_s = 1e-3;
  std::vector<double> t_s, u_V, y_um;
  std::vector<double> y_true_um;  ///< noise-free displacement (simulation only; else empty)
};

/// Runs one experiment on `rig`: the rig is first put at rest under `B` (a real
/// run would hold B for a while; the sine starts at its bias, so there is no
/// step), then `u(t_k) = B + A sin(2 pi f t_k)` for the point's whole duration.
SineRecord run_sine_experiment(SimulatedRig& rig, const SinePoint& point);

/// Output of `model` driven by `u_V` in the rig's cycle convention, with
/// `io_delay_samples` of I/O delay and the exact ZOH discretisation of G. The
/// model starts at its steady state for u_V[0] (consistent initial state).
std::vector<double> simulate_hammerstein(const HammersteinModel& model, const std::vector<double>& u_V,
                                         double sample_time_s, int io_delay_samples);

/// How well a prediction matches a measurement over samples [begin, end).
struct PredictionMetrics {
  double nrmse = 0.0;         ///< rms(y - y_hat) / rms(y - mean(y)); 0 is perfect
  double rms_error_um = 0.0;
  double max_error_um = 0.0;  ///< max |y - y_hat|
  double mean_error_um = 0.0; ///< mean(y - y_hat): the DC (offset) part of the error
};

/// @throws std::invalid_argument on mismatched sizes or an empty range.
PredictionMetrics prediction_metrics(const std::vector<double>& y_um, const std::vector<double>& y_hat_um,
                                     size_t begin, size_t end);

}  // namespace pvcgel::control::identification
