#pragma once
/// @file
/// The paper's tracking comparison (Section V-C, Table III) on the simulated rig.

#include <array>
#include <string>
#include <vector>

#include "control/closed_loop.hpp"

namespace pvcgel::tools {

/// Table III of the paper: mean / max |e| (um) per reference, for pid,
/// inverse_pid and inverse_pid_dob (the fourth mode is ours).
struct PaperRow {
  const char* reference;
  std::array<double, 3> mean_um, max_um;
};
inline constexpr std::array<PaperRow, 4> kPaperTableIII{{
    {"0.1Hz", {0.685, 0.130, 0.072}, {1.914, 0.501, 0.467}},
    {"0.5Hz", {0.968, 0.311, 0.121}, {2.430, 0.753, 0.482}},
    {"1Hz", {1.024, 0.379, 0.167}, {2.552, 1.074, 0.613}},
    {"multi", {0.394, 0.178, 0.078}, {1.300, 0.666, 0.421}},
}};

/// How the comparison is run.
struct PaperBenchOptions {
  control::TuningTarget tuning{45.0, 60.0};  ///< same target for every mode
  /// Base controller settings (mode and tuning are set per run from the above).
  control::ControllerConfig controller{};
  double duration_s = 60.0;
  double settle_s = 20.0;  ///< errors are evaluated after this
  control::SimRigConfig rig{};
  control::HammersteinModel model = control::paper_model(2);
  bool keep_traces = false;
};

/// Result for one reference and one mode.
struct ModeResult {
  control::ControllerMode mode;
  control::TrackingErrors errors;
  control::PidGains gains;
  control::LoopMargins margins;
  control::ClosedLoopTrace trace;
  /// Mean |r - y_true| of the same controller on a rig that equals the model
  /// (no mismatch, no hysteresis/creep, no noise): the part of the error due
  /// to finite loop bandwidth alone.
  double bandwidth_only_mean_um = 0.0;
};

/// Results for one reference.
struct ReferenceResult {
  std::string name;
  std::array<ModeResult, 4> modes;
};

/// The whole comparison.
struct PaperBenchResult {
  std::vector<ReferenceResult> references;
  double noise_floor_um = 0.0;  ///< mean |measured - true| displacement over all runs
  double steps_per_second = 0.0;
};

/// Runs every paper reference under every mode (same rig seed for each run).
PaperBenchResult run_paper_bench(const PaperBenchOptions& options);

/// Table III layout with the paper beside ours, reductions versus pid.
std::string format_table(const PaperBenchResult& r, const PaperBenchOptions& o);
/// Machine-readable form (schema in the README).
std::string to_json(const PaperBenchResult& r, const PaperBenchOptions& o);
/// True when mean |e| of inverse_pid_dob < inverse_pid < pid for this reference.
bool paper_ranking_holds(const ReferenceResult& r);

}  // namespace pvcgel::tools
