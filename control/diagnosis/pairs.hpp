#pragma once
/// @file
/// Mixtures (internal): the leader fitted jointly with the most promising second effects, the best pair's
/// second beside runners-up in the leader's place (the exchange step), each member refitted alone, and the
/// test that names both (each significant on held-out data and material).

#include <span>
#include <string>
#include <vector>

#include "control/diagnosis/candidates.hpp"
#include "control/diagnosis/diagnosis.hpp"
#include "control/diagnosis/fit_problem.hpp"

namespace pvcgel::control::diagnosis::detail {

/// A fitted mixture of two effects.
struct PairFit {
  std::vector<Effect> effects;
  Nominal nominal;
  std::vector<std::vector<double>> y;  ///< its prediction, all samples
  double gain = 1.0;
  ModelErrors errors;
  double score = INFINITY;
};

/// The best single effect fitted jointly with each of the most promising second effects, then the best of
/// those pairs' second effect beside the best runners-up in the leader's place: the best pair.
PairFit best_pair(DiagnosisResult& res, Problem& problem, const std::vector<Series>& data, const DataScale& scale,
                  const DiagnosisOptions& o);

/// Each member of `pair` refitted alone from its value in the pair, kept where it fits better; re-ranks.
void refit_members_alone(DiagnosisResult& res, const PairFit& pair, Problem& problem, const std::vector<Series>& data,
                         const DataScale& scale, const DiagnosisOptions& o);

/// Where a nominal refit (gain and k) fitted with `effects` stops at its tolerance.
std::vector<std::string> refit_at_bounds_with(double gain, Nominal k, std::span<const Effect> effects,
                                              const DiagnosisOptions& o);

/// The block length held-out comparisons of fits on this rig average over: o.significance_block_s, or ten
/// of G's slowest time constants (at the time scale of `k`) when that is shorter.
double pair_block_s(const Problem& problem, Nominal k, const DiagnosisOptions& o);

/// Whether both effects of `pair` are named; orders the pair dominant first.
bool judge_pair(DiagnosisResult& res, PairFit& pair, Problem& problem, const std::vector<Series>& data,
                const Excess& excess, const DiagnosisOptions& o);

/// Whether the second effect is withheld because the pair's refit stops where it can stand in for it, and
/// the leader alone with a wider nominal refit explains the held-out data about as well as the pair.
bool withhold_second(DiagnosisResult& res, const PairFit& pair, Problem& problem, const std::vector<Series>& data,
                     const DataScale& scale, const DiagnosisOptions& o);

}  // namespace pvcgel::control::diagnosis::detail
