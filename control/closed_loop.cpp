#include "control/closed_loop.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace pvcgel::control {

namespace {

/// The tracking errors' sums, maximum and saturated count over the samples after settling; finish() writes
/// them, the sums as means.
struct ErrorSums {
  double abs = 0.0, sq = 0.0, abs_true = 0.0, noise = 0.0, max_abs = 0.0;
  long count = 0, saturated = 0;

  void add(double r, double y, double y_true, bool is_saturated) {
    const double err = r - y;
    abs += std::abs(err);
    sq += err * err;
    max_abs = std::max(max_abs, std::abs(err));
    abs_true += std::abs(r - y_true);
    noise += std::abs(y - y_true);
    if (is_saturated) ++saturated;
    ++count;
  }
  void finish(TrackingErrors& e) const {
    e.max_abs_um = max_abs;
    e.saturated_samples = saturated;
    if (count == 0) return;
    const auto n_eval = static_cast<double>(count);
    e.mean_abs_um = abs / n_eval;
    e.rms_um = std::sqrt(sq / n_eval);
    e.mean_abs_true_um = abs_true / n_eval;
    e.noise_mean_abs_um = noise / n_eval;
  }
};

void append(ClosedLoopTrace& trace, double t, double r, double y, double y_true, const ControlOutput& out) {
  trace.t_s.push_back(t);
  trace.r_um.push_back(r);
  trace.y_um.push_back(y);
  trace.y_true_um.push_back(y_true);
  trace.u_V.push_back(out.voltage_V);
  trace.d_hat.push_back(out.d_hat);
}

}  // namespace

ClosedLoopRun run_closed_loop(SimulatedRig& rig, Controller& ctl, const MultiSine& ref, double duration_s,
                              double settle_s, bool keep_trace) {
  const double Ts = ctl.config().sample_time_s;
  const long n = std::lround(duration_s / Ts);
  const int preview = ctl.preview_samples();
  std::array<double, 32> window{};
  const int len = std::min<int>(preview + 1, static_cast<int>(window.size()));
  for (int i = 0; i < len; ++i) window[static_cast<size_t>(i)] = ref(i * Ts);

  ctl.reset_steady_state(window[0]);
  rig.reset_steady_state(ctl.last_voltage_V());

  ClosedLoopRun run;
  if (keep_trace) {
    for (auto* v : {&run.trace.t_s, &run.trace.r_um, &run.trace.y_um, &run.trace.y_true_um, &run.trace.u_V,
                    &run.trace.d_hat})
      v->reserve(static_cast<size_t>(n));
  }
  ErrorSums sums;
  for (long k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * Ts;
    const double y_true = rig.true_displacement_um();
    const double y = rig.measure();
    const auto out = ctl.step(std::span<const double>(window.data(), static_cast<size_t>(len)), y);
    rig.apply(out.voltage_V);
    if (t >= settle_s) sums.add(window[0], y, y_true, out.status == ControlOutput::Status::saturated);
    if (keep_trace) append(run.trace, t, window[0], y, y_true, out);
    for (int i = 0; i + 1 < len; ++i) window[static_cast<size_t>(i)] = window[static_cast<size_t>(i + 1)];
    window[static_cast<size_t>(len - 1)] = ref(static_cast<double>(k + len) * Ts);
  }
  sums.finish(run.errors);
  return run;
}

}  // namespace pvcgel::control
