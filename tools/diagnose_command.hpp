#pragma once
/// @file
/// `pvcgel diagnose --model MODEL.toml [--json REPORT.json] [--predict PREFIX]
/// [--report DIR] [--out AUGMENTED.toml] REC.csv [REC.csv ...]`: locate the
/// sim-to-real mismatch, name the missing physics, fit it, and show on held-out
/// data that the fit improved (control/diagnosis).

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "control/diagnosis/diagnosis.hpp"

namespace pvcgel::tools {

/// Everything `pvcgel diagnose` can be told.
struct DiagnoseArgs {
  std::string model;                    ///< TOML with a [model] table (or a full daemon config)
  std::vector<std::string> recordings;  ///< daemon recordings
  std::string json;                     ///< machine-readable report
  std::string predict;                  ///< PREFIX: PREFIX<k>.csv with t_s,y_um_baseline,y_um_fitted
  std::string report;                   ///< directory for report.md and PNG plots
  std::string out;                      ///< augmented model (default: see augmented_model_path)
  bool quiet = false;
  int threads = 0;                      ///< threads the candidate fits run on (0: every core)
  bool progress = false;                ///< each stage's progress on stderr (the command line: unless --quiet)
};

/// A model file read for diagnosis.
struct LoadedModel {
  control::HammersteinModel model = control::paper_model(2);  ///< replaced by the file's
  int io_delay_samples = 1;
  bool io_delay_declared = false;  ///< the file has `[model] io_delay_samples` (else it is estimated)
  double voltage_max_V = 0.0;      ///< `[controller] voltage_max_V` (0: absent; the augmented model then sets
                                   ///< the controller's limit below a turnover of f itself)
  std::string other_tables;        ///< the file's tables other than [model] and [sim], as TOML (kept in the augmented model)
};

/// Reads `[model]` (poly, G_num, G_den, optional io_delay_samples) from `path`.
/// @throws std::runtime_error "PATH:LINE: key: reason" for an unstable G, an
///         unparsable file or a bad key.
LoadedModel load_model(const std::string& path);

/// Where the augmented model goes: --out, else DIR/augmented_model.toml with
/// --report, else PREFIXaugmented_model.toml with --predict, else next to the
/// JSON (REPORT.augmented.toml); empty when none of them is given.
std::string augmented_model_path(const DiagnoseArgs& args);

/// The augmented model file: `[model]` (what the controller uses: the nominal
/// model with the diagnosis' refit of gain, G's time scale and f's shape) and
/// `[[model.effect]]` (the diagnosed effects, dominant first, for the controller
/// to compensate), the user's other tables unchanged, and a `[sim]` table whose
/// `[sim.truth]` is the same model with the same effects in
/// `[[sim.truth.effect]]`, so pvcgeld's sim backend runs it; without the
/// user's `[controller]`, one whose `period_s` is `sample_time_s` (the
/// recordings': the sim backend then runs at their rate).
std::string augmented_model_toml(const LoadedModel& model, const control::diagnosis::DiagnosisResult& result,
                                 double sample_time_s, const std::string& comment);

/// The JSON report (schema of issue 7).
std::string diagnosis_json(const control::diagnosis::DiagnosisResult& result, const std::vector<std::string>& recordings,
                           const std::vector<long>& skipped_rows, double cpu_s);

/// The recordings, checked against the model (a bad one names its file), and the rows each skipped.
struct LoadedRecordings {
  std::vector<control::diagnosis::Series> data;
  std::vector<long> skipped;
};

/// Reads args.recordings. @throws std::runtime_error "PATH: reason" for a bad recording.
LoadedRecordings load_recordings(const DiagnoseArgs& args, const LoadedModel& model);

/// The diagnosis options the command runs with: the model file's I/O delay and controller range, the
/// threads and progress of `args`.
control::diagnosis::DiagnosisOptions diagnosis_options(const DiagnoseArgs& args, const LoadedModel& model);

/// What run_diagnose produced (for tests).
struct DiagnoseOutcome {
  control::diagnosis::DiagnosisResult result;
  std::string summary;
  std::string augmented_model_path;  ///< empty when not written
};

/// Runs the command. @throws std::runtime_error naming file, line and reason on bad input.
DiagnoseOutcome run_diagnose(const DiagnoseArgs& args);

/// Adds `diagnose` to the app.
void add_diagnose_command(CLI::App& app);

}  // namespace pvcgel::tools
