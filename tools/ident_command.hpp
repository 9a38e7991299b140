#pragma once
/// @file
/// `pvcgel ident`: describing-function identification from sine experiments,
/// on the simulated rig (`--sim`), from recordings (`--from DIR`), or on a
/// running daemon over DDS (`--rig ID`).

#include <CLI/CLI.hpp>
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "control/hammerstein_model.hpp"
#include "control/identification/excitation_plan.hpp"
#include "control/identification/identification.hpp"
#include "control/identification/sine_experiment.hpp"
#include "daemon/recorder.hpp"

namespace pvcgel::tools {

/// Everything `pvcgel ident` can be told.
struct IdentArgs {
  bool sim = false;              ///< run the plan on the simulated rig
  std::string rig;               ///< run the plan on this rig (a pvcgeld over DDS)
  int domain = 0;                ///< --rig: DDS domain
  std::string dds_config;        ///< --rig: Cyclone DDS XML (default $PVCGEL_DDS_CONFIG)
  std::string from;              ///< directory of recordings, one sine experiment per *.csv
  std::string validation_dir;    ///< held-out recordings (default: FROM/validation if present)
  std::string out;               ///< model TOML to write
  std::string report;            ///< directory for report.md and PNG plots
  std::string save_recordings;   ///< --sim, --rig: write every experiment as a recording here
  std::string config;            ///< --sim: TOML with a [sim] table (default: the paper rig)
  bool ideal = false;            ///< --sim: hysteresis and creep off (truth exactly Hammerstein)
  std::uint64_t seed = 1;
  control::identification::ExcitationPlan::Grid grid{};
  double settle_s = 10.0;        ///< --from: used when a recording has no `# settle_s:` header
  int min_periods = 3;
  control::identification::IdentificationOptions options{};
  std::vector<double> validation_frequencies_Hz{0.1, 1.0};  ///< the paper's Fig. 10
  double validation_amplitude_V = 400.0, validation_bias_V = 450.0;
  bool quiet = false;            ///< no progress lines on stderr
};

/// What `run_ident` produced (for tests and callers).
struct IdentOutcome {
  control::identification::IdentificationResult result;
  std::string summary;             ///< the text printed on stdout
  double cpu_extract_fit_s = 0.0;  ///< CPU time of extraction and fits only
  bool model_written = false;
};

/// The fitted G cannot be controlled (e.g. unstable, non-minimum phase): no
/// model is written. `summary` holds the analysis that shows why.
struct IdentRefused : std::runtime_error {
  IdentRefused(const std::string& why, std::string summary_text);
  std::string summary;
};

/// Runs the identification the way the command line does.
/// @throws IdentRefused when G is refused for control;
///         std::runtime_error with a user-facing message otherwise (e.g. --rig,
///         unreadable directory, too few valid points).
IdentOutcome run_ident(const IdentArgs& args);

/// The `[model]` table the daemon reads (`poly`, `G_num`, `G_den`), with `#` comment lines first.
std::string model_toml(const control::HammersteinModel& model, const std::string& comment);

/// Writes an experiment as a recording, with the daemon's writer (daemon/recorder.hpp):
/// mode open_loop, state RUNNING; r_um and e_um are nan (there is no reference).
void write_sine_recording(const std::filesystem::path& path, const control::identification::SineRecord& record,
                          const daemon::RecordingHeader& header);

/// Adds `ident` to the app.
void add_ident_command(CLI::App& app);

}  // namespace pvcgel::tools
