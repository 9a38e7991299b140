#include "control/closed_loop.hpp"

#include <array>
#include <cmath>

namespace pvcgel::control {

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
  auto& e = run.errors;
  double sum_abs = 0.0, sum_sq = 0.0, sum_abs_true = 0.0, sum_noise = 0.0;
  long count = 0;
  for (long k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * Ts;
    const double y_true = rig.true_displacement_um();
    const double y = rig.measure();
    const auto out = ctl.step(std::span<const double>(window.data(), static_cast<size_t>(len)), y);
    rig.apply(out.voltage_V);
    if (t >= settle_s) {
      const double err = window[0] - y;
      sum_abs += std::abs(err);
      sum_sq += err * err;
      e.max_abs_um = std::max(e.max_abs_um, std::abs(err));
      sum_abs_true += std::abs(window[0] - y_true);
      sum_noise += std::abs(y - y_true);
      if (out.status == ControlOutput::Status::saturated) ++e.saturated_samples;
      ++count;
    }
    if (keep_trace) {
      run.trace.t_s.push_back(t);
      run.trace.r_um.push_back(window[0]);
      run.trace.y_um.push_back(y);
      run.trace.y_true_um.push_back(y_true);
      run.trace.u_V.push_back(out.voltage_V);
      run.trace.d_hat.push_back(out.d_hat);
    }
    for (int i = 0; i + 1 < len; ++i) window[static_cast<size_t>(i)] = window[static_cast<size_t>(i + 1)];
    window[static_cast<size_t>(len - 1)] = ref(static_cast<double>(k + len) * Ts);
  }
  if (count > 0) {
    const auto n_eval = static_cast<double>(count);
    e.mean_abs_um = sum_abs / n_eval;
    e.rms_um = std::sqrt(sum_sq / n_eval);
    e.mean_abs_true_um = sum_abs_true / n_eval;
    e.noise_mean_abs_um = sum_noise / n_eval;
  }
  return run;
}

}  // namespace pvcgel::control
