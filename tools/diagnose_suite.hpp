#pragma once
/// @file
/// The blind suite for `pvcgel diagnose`: generated recordings with a concealed
/// effect, labels kept apart, scored by verdict accuracy, false alarms, the
/// held-out RMSE ratio on correct cases and the time per case.

#include <array>
#include <cstdint>
#include <iosfwd>
#include <map>
#include <string>
#include <vector>

#include "control/diagnosis/generator.hpp"

namespace pvcgel::tools {

/// Scores of one suite run.
struct BlindSuiteResult {
  static constexpr int kLabels = 12;  ///< none, the ten effects, unexplained (verdict only)
  std::array<std::array<int, kLabels>, kLabels> confusion{};  ///< [truth][verdict]
  int cases = 0, correct = 0;
  int none_cases = 0, false_alarms = 0;      ///< "none" truths diagnosed as anything else
  int out_of_spec = 0;                       ///< cases whose effect missed the concealment targets
  double worst_ratio = 0.0, mean_ratio = 0.0;  ///< held-out RMSE fitted / nominal on correct effect cases
  double max_case_s = 0.0, mean_case_s = 0.0;  ///< diagnosis wall time per case
  [[nodiscard]] double accuracy() const { return cases ? static_cast<double>(correct) / cases : 0.0; }
};

/// Runs `cases` blind cases (blind_suite_plan(cases, seed)); one line per case
/// goes to `log` (the truth is printed only after the verdict). With
/// `save_dir`, every case is also written there as a daemon recording
/// (caseNN.csv), with the nominal model (model.toml) and, apart, labels.csv.
BlindSuiteResult run_blind_suite(int cases, std::uint64_t seed, std::ostream& log,
                                 const control::diagnosis::GeneratorOptions& options = {},
                                 const std::string& save_dir = "");

/// The confusion matrix and the scores as text.
std::string format_suite(const BlindSuiteResult& r);

}  // namespace pvcgel::tools

namespace pvcgel::tools {

/// Scores of a suite of case directories made elsewhere (`pvcgel bench diagnose --suite DIR`).
struct DirectorySuiteResult {
  static constexpr int kLabels = 12;  ///< as BlindSuiteResult: none, the ten effects, unexplained
  std::array<std::array<int, kLabels>, kLabels> confusion{};  ///< single effects and none: [truth][verdict]
  int single_cases = 0, single_correct = 0;
  int none_cases = 0, false_alarms = 0;
  int mixture_cases = 0, mixture_both_named = 0, mixture_dominant_correct = 0;
  int failed = 0;                                ///< cases the tool stopped on with an error
  std::vector<double> ratios;                    ///< held-out RMSE fitted / nominal on correct effect cases
  std::vector<double> ratios_aligned;            ///< the same against the nominal with offset and start state fitted
  /// The ratios of the correct effect cases whose held-out data show an effect: the nominal's held-out RMSE
  /// at least kHeldOutShowsEffect times the estimated noise. Below that the held-out blocks fall where the
  /// effect does not act (a dead zone seen only in the step from rest, which the fitting segment holds), and
  /// no model can bring the ratio under 1 / kHeldOutShowsEffect.
  static constexpr double kHeldOutShowsEffect = 1.5;
  std::vector<double> ratios_held_out_shows_effect;
  double max_case_s = 0.0, mean_case_s = 0.0;
  int jobs = 1, threads_per_case = 1;  ///< how the suite ran: `jobs` cases at once, each fitting on that many threads
  /// The slowest cases diagnosed again one at a time on every core, as `pvcgel diagnose` runs alone
  /// (run_directory_suite's `retime_slowest`): {case, seconds}, slowest first; their threads; and how many
  /// of them gave another verdict or mixture the second time (the answer does not depend on the threads).
  std::vector<std::pair<std::string, double>> alone_s;
  int alone_threads = 1, alone_answer_changed = 0;
  int cases = 0;
  /// Cases whose nominal refit stopped at a tolerance (NominalRefit::at_bounds), and how many of them,
  /// and of the others, were scored right (the verdict for a single effect or none, both named for a mixture).
  int refit_at_bound = 0, refit_at_bound_right = 0, refit_inside_right = 0;
  /// Single-effect and none cases that name a second effect (a false one by the labels); cases with a
  /// second effect withheld (DiagnosisResult::withheld_second), and how many of those the labels hold.
  int false_second = 0, withheld = 0, withheld_true = 0;
  /// Cases diagnosed with the widened refit (NominalRefit::widened), and how many of them were scored right.
  int widened = 0, widened_right = 0;
  /// Single-effect cases answered with ambiguous_with, those whose verdict is right, and those whose verdict
  /// is wrong but whose ambiguous names hold the truth (a hedge that holds the answer, with an experiment).
  int single_ambiguous = 0, single_ambiguous_right = 0, single_truth_among_ambiguous = 0;
  /// Single effects and mixtures whose every effect leaves at least kVisibleAfterRefit times the noise RMS
  /// after a gain and offset refit, by the labels' own measure (the `params` column's
  /// ratio_after_gain_offset_refit, when the labels have it), and how many of them were scored right: the
  /// cases the nuisance-only refit cannot simply absorb.
  static constexpr double kVisibleAfterRefit = 1.5;
  int visible_single_cases = 0, visible_single_correct = 0, visible_mixture_cases = 0, visible_mixture_both_named = 0;
  /// Mixtures without both effects named, by the best pair the diagnosis fitted (DiagnosisResult::second_effect_test):
  /// no pair fitted, another pair than the labels', or the labels' pair with what kept its second effect out
  /// (second_effect_shortfalls; a case with several counts under each).
  int mixture_missed_no_pair = 0, mixture_missed_other_pair = 0, mixture_missed_labels_pair = 0;
  /// Of those with another pair best, how many had the labels' pair fitted too (SecondEffectTest::tried): the
  /// rest never fitted the labels' second effect beside the leader.
  int mixture_other_pair_labels_fitted = 0;
  /// Of those with a pair fitted, how many had their best single effect at the noise already (kSingleAtTheNoise).
  int mixture_missed_single_at_noise = 0;
  std::map<std::string, int> mixture_labels_pair_shortfalls;
  /// Single effects by the labels' `form` column (the generator's own form of the effect, when the labels
  /// have one), as "effect/form": {right, cases}. Which forms the candidates miss, without reading the labels.
  std::map<std::string, std::array<int, 2>> single_by_form;
};

/// Runs `pvcgel diagnose` on every case of DIR (caseNNN/model.toml and recK.csv;
/// labels from DIR/labels.csv, read only to score) with `jobs` parallel cases.
/// One line per case goes to `log`. `limit` > 0 stops after that many cases. With `jobs` > 1 each case
/// runs on a share of the cores, so `retime_slowest` > 0 then diagnoses that many of the slowest cases
/// again, one at a time on every core: the time a user waits for one case.
DirectorySuiteResult run_directory_suite(const std::string& dir, int jobs, std::ostream& log, int limit = 0,
                                         int retime_slowest = 0);

/// The confusion matrix and the scores, each with the target and the ratio to it.
std::string format_directory_suite(const DirectorySuiteResult& r);

}  // namespace pvcgel::tools
