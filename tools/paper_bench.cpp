#include "tools/paper_bench.hpp"

#include "control/text_format.hpp"

#include <chrono>
#include <sstream>

namespace pvcgel::tools {

using control::ControllerMode;

PaperBenchResult run_paper_bench(const PaperBenchOptions& o) {
  PaperBenchResult result;
  double noise_sum = 0.0;
  long runs = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (const auto& name : control::kPaperReferenceNames) {
    const auto ref = *control::paper_reference(name);
    ReferenceResult rr{name, {}};
    for (auto m : control::kAllModes) {
      control::ControllerConfig cc = o.controller;
      cc.sample_time_s = o.rig.sample_time_s;
      cc.tuning = o.tuning;
      cc.mode = m;
      control::Controller ctl(o.model, cc);
      control::SimulatedRig rig(o.rig);
      auto run = control::run_closed_loop(rig, ctl, ref, o.duration_s, o.settle_s, o.keep_traces);
      auto& mr = rr.modes[static_cast<size_t>(m)];
      mr = {m, run.errors, ctl.gains(m), ctl.margins(m), std::move(run.trace), 0.0};
      // The same loop on a rig that is exactly the model isolates the bandwidth-limited error.
      control::SimulatedRig ideal_rig(o.rig.exactly(o.model));
      control::Controller ideal_ctl(o.model, cc);
      mr.bandwidth_only_mean_um =
          control::run_closed_loop(ideal_rig, ideal_ctl, ref, o.duration_s, o.settle_s, false).errors.mean_abs_true_um;
      noise_sum += run.errors.noise_mean_abs_um;
      ++runs;
    }
    result.references.push_back(std::move(rr));
  }
  const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  result.steps_per_second = 2.0 * static_cast<double>(runs) * o.duration_s / o.rig.sample_time_s / dt;
  result.noise_floor_um = noise_sum / static_cast<double>(runs);
  return result;
}

bool paper_ranking_holds(const ReferenceResult& r) {
  const auto mean = [&](ControllerMode m) { return r.modes[static_cast<size_t>(m)].errors.mean_abs_um; };
  return mean(ControllerMode::inverse_pid_dob) < mean(ControllerMode::inverse_pid) &&
         mean(ControllerMode::inverse_pid) < mean(ControllerMode::pid);
}

namespace {

/// Table III beside ours: each reference's mean and max |e| per mode, the paper's next to it.
void write_table_iii(std::ostream& os, const PaperBenchResult& r) {
  os << "                     |        PID        |    inverse/PID    |  inverse/PID/DOB  | inv/PID/DOB/FF (ours)\n";
  os << "reference            |   ours    paper   |   ours    paper   |   ours    paper   |   ours   vs PID\n";
  os << "---------------------+-------------------+-------------------+-------------------+------------------\n";
  for (size_t i = 0; i < r.references.size(); ++i) {
    const auto& rr = r.references[i];
    const auto& paper = kPaperTableIII[i];
    for (int stat = 0; stat < 2; ++stat) {
      auto val = [&](size_t m) {
        const auto& e = rr.modes[m].errors;
        return stat == 0 ? e.mean_abs_um : e.max_abs_um;
      };
      const auto& pp = stat == 0 ? paper.mean_um : paper.max_um;
      os << control::format("%-6s (%s)         | %6.3f   %6.3f   | %6.3f   %6.3f   | %6.3f   %6.3f   | %6.3f  %+5.0f%%\n",
                            rr.name.c_str(), stat == 0 ? "mean" : "max ", val(0), pp[0], val(1), pp[1], val(2), pp[2],
                            val(3), 100.0 * (val(3) / val(0) - 1.0));
    }
  }
}

/// Each mode's reduction of mean |e| against PID, ours and the paper's, and the two checks the bench makes.
void write_reductions(std::ostream& os, const PaperBenchResult& r) {
  os << "\nReduction of mean |e| versus PID (ours / paper):\n";
  for (size_t i = 0; i < r.references.size(); ++i) {
    const auto& rr = r.references[i];
    const auto& paper = kPaperTableIII[i];
    auto red = [](double x, double ref) { return 100.0 * (1.0 - x / ref); };
    const double pid = rr.modes[0].errors.mean_abs_um;
    os << control::format("  %-6s inverse/PID %5.1f%% / %5.1f%%   inverse/PID/DOB %5.1f%% / %5.1f%%   "
                          "inv/PID/DOB/FF %5.1f%%   ranking DOB < inverse < PID: %s   FF within 2x noise floor: %s\n",
                          rr.name.c_str(), red(rr.modes[1].errors.mean_abs_um, pid), red(paper.mean_um[1], paper.mean_um[0]),
                          red(rr.modes[2].errors.mean_abs_um, pid), red(paper.mean_um[2], paper.mean_um[0]),
                          red(rr.modes[3].errors.mean_abs_um, pid), paper_ranking_holds(rr) ? "yes" : "NO",
                          rr.modes[3].errors.mean_abs_um <= 2.0 * r.noise_floor_um ? "yes" : "NO");
  }
}

/// The error without sensor noise on this rig beside that on a rig equal to the model (bandwidth alone).
void write_error_sources(std::ostream& os, const PaperBenchResult& r) {
  os << "\nWhere the error comes from, mean |r - y_true| in um (no sensor noise): on this rig / on a rig that\n"
        "equals the model (finite loop bandwidth alone). Where the two are close, the mode is limited by its\n"
        "bandwidth, not by model mismatch, and a disturbance observer cannot help:\n";
  for (const auto& rr : r.references) {
    os << control::format("  %-6s", rr.name.c_str());
    for (const auto& m : rr.modes) {
      os << control::format("   %s %.3f / %.3f", std::string(control::to_string(m.mode)).c_str(),
                            m.errors.mean_abs_true_um, m.bandwidth_only_mean_um);
    }
    os << "\n";
  }
}

}  // namespace

std::string format_table(const PaperBenchResult& r, const PaperBenchOptions& o) {
  std::ostringstream os;
  os << control::format("Simulated rig (default: the paper rig, truth n=3, model n=2), every mode's PID tuned to crossover %.0f rad/s, phase "
                        "margin %.0f deg on the plant it sees;\nerrors |r - y_measured| over %.0f..%.0f s. "
                        "Sensor-noise floor (mean |noise|): %.3f um.\n\n",
                        o.tuning.crossover_rad_s, o.tuning.phase_margin_deg, o.settle_s, o.duration_s, r.noise_floor_um);
  write_table_iii(os, r);
  write_reductions(os, r);
  write_error_sources(os, r);
  return os.str();
}

std::string to_json(const PaperBenchResult& r, const PaperBenchOptions& o) {
  std::ostringstream os;
  os.precision(6);
  os << "{\n  \"noise_floor_um\": " << r.noise_floor_um << ",\n";
  os << "  \"tuning\": {\"crossover_rad_s\": " << o.tuning.crossover_rad_s
     << ", \"phase_margin_deg\": " << o.tuning.phase_margin_deg << "},\n";
  os << "  \"steps_per_second\": " << r.steps_per_second << ",\n  \"references\": [\n";
  for (size_t i = 0; i < r.references.size(); ++i) {
    const auto& rr = r.references[i];
    os << "    {\"name\": \"" << rr.name << "\", \"paper_ranking_holds\": "
       << (paper_ranking_holds(rr) ? "true" : "false") << ", \"modes\": {";
    for (size_t m = 0; m < 4; ++m) {
      const auto& mr = rr.modes[m];
      os << (m ? ", " : "") << "\"" << control::to_string(mr.mode) << "\": {\"mean_um\": " << mr.errors.mean_abs_um
         << ", \"max_um\": " << mr.errors.max_abs_um << ", \"rms_um\": " << mr.errors.rms_um
         << ", \"mean_true_um\": " << mr.errors.mean_abs_true_um << ", \"kp\": " << mr.gains.kp
         << ", \"ki\": " << mr.gains.ki << ", \"kd\": " << mr.gains.kd << "}";
    }
    os << "}}" << (i + 1 < r.references.size() ? "," : "") << "\n";
  }
  os << "  ]\n}\n";
  return os.str();
}

}  // namespace pvcgel::tools
