#pragma once
/// @file
/// Alignment as nuisance (internal): each recording's start state, the I/O delay (sub-sample estimate,
/// whole samples used) checked against the model file, and a second pass at the delay a leading candidate
/// fits clearly better with.

#include <optional>
#include <string>
#include <vector>

#include "control/diagnosis/diagnosis.hpp"
#include "control/diagnosis/fit_problem.hpp"

namespace pvcgel::control::diagnosis::detail {

/// How much less squared error (in noise variances) a fit's nuisance choice, a start state or a longer
/// I/O delay, must leave to count as evidence: far above chance for one parameter (chi-squared with one
/// degree of freedom exceeds 25 with probability 6e-7), and above the few noise variances a `none`
/// recording's nominal error moves between neighbouring delays (at most 7.8 over the 100 `none`
/// recordings of seed 31 and the fresh sets' `none` answers, 2026-11-30).
inline constexpr double kClearlyBetterNoiseVariances = 25.0;

/// Refines each recording's start state on its first window with the nominal refitted as `k`; returns
/// whether any moved.
bool refine_starts(Problem& p, const std::vector<Series>& data, const DiagnosisOptions& o, Nominal k);

/// The start states, then the I/O delay; leaves `p` set to what the analysis uses.
Alignment estimate_alignment(Problem& p, const std::vector<Series>& data, const DiagnosisOptions& o);

/// What the first pass hands the second when its leading candidate fits clearly better at another delay.
struct SecondPass {
  Alignment alignment;  ///< the first pass's
  std::vector<CandidateResult> candidates;  ///< the first pass's fits: the second pass's starts
  int delay_samples = 0;
  std::string leader;
};

/// The second pass's alignment: the first pass's, at `delay_samples`.
Alignment realign(Problem& p, Alignment a, int delay_samples, const std::string& leader);

/// A delay other than the one in use, and the candidate that fits the data clearly better with it.
struct DelayChoice {
  int delay_samples = 0;
  std::string candidate;
};

/// The delay one of the two leading candidates fits the fit segment clearly better with, if any.
std::optional<DelayChoice> leading_delay(const DiagnosisResult& res, Problem& problem, const std::vector<Series>& data,
                                         const DataScale& scale, const DiagnosisOptions& o);

}  // namespace pvcgel::control::diagnosis::detail
