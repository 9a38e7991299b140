#pragma once
/// @file
/// Accelerated closed-loop simulation of a controller on a simulated rig.

#include <vector>

#include "control/controller.hpp"
#include "control/reference_signal.hpp"
#include "control/simulated_rig.hpp"

namespace pvcgel::control {

/// Per-sample record of a run (kept only when asked for).
struct ClosedLoopTrace {
  std::vector<double> t_s, r_um, y_um, y_true_um, u_V, d_hat;
};

/// Tracking errors over the evaluation window (after start-up transients).
struct TrackingErrors {
  double mean_abs_um = 0.0;       ///< mean |r - y_measured| (what a lab reports)
  double max_abs_um = 0.0;        ///< max |r - y_measured|
  double rms_um = 0.0;
  double mean_abs_true_um = 0.0;  ///< mean |r - y_true|: without sensor noise
  double noise_mean_abs_um = 0.0; ///< mean |y_measured - y_true|: the floor
  long saturated_samples = 0;
};

/// A finished run.
struct ClosedLoopRun {
  TrackingErrors errors;
  ClosedLoopTrace trace;
};

/// Runs `duration_s` of the loop as fast as the CPU allows. Both the rig and
/// the controller start at the nominal steady state for r(0) (the rig then
/// settles to where its truth takes it: that is part of the transient), and
/// errors are evaluated from `settle_s` on.
ClosedLoopRun run_closed_loop(SimulatedRig& rig, Controller& controller, const MultiSine& reference,
                              double duration_s, double settle_s, bool keep_trace);

}  // namespace pvcgel::control
