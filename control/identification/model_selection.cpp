#include "control/identification/model_selection.hpp"
#include "control/text_format.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "control/odd_polynomial.hpp"

namespace pvcgel::control::identification {

namespace {

/// Where f stops increasing on [0, limit], if it does (f'(0) <= 0 counts as 0 V).
std::optional<double> turnover(const PolynomialCandidate& c, double limit_V) {
  if (c.c.empty() || !(c.c[0] > 0.0)) return 0.0;
  return OddPolynomial(c.c, "ident.poly").first_turnover(limit_V);
}

std::vector<double> mean_nrmse(size_t candidates, const std::vector<std::vector<PredictionMetrics>>& metrics) {
  std::vector<double> mean(candidates, 0.0);
  for (const auto& per_record : metrics) {
    if (per_record.size() < candidates) throw std::invalid_argument("validation metrics missing for some n");
    for (size_t n = 0; n < candidates; ++n) mean[n] += per_record[n].nrmse / static_cast<double>(metrics.size());
  }
  return mean;
}

}  // namespace

ModelChoice choose_by_validation(const NonlinearityFit& fit, const std::vector<std::vector<PredictionMetrics>>& metrics,
                                 const ModelChoiceOptions& o) {
  if (metrics.empty()) throw std::invalid_argument("no held-out validation to choose n by");
  ModelChoice choice;
  choice.mean_nrmse = mean_nrmse(fit.candidates.size(), metrics);
  double best = INFINITY;
  for (size_t i = 0; i < fit.candidates.size(); ++i) {
    const auto turn = turnover(fit.candidates[i], o.amplifier_max_V);
    if (turn && *turn <= o.highest_bias_V) choice.mean_nrmse[i] = NAN;
    else best = std::min(best, choice.mean_nrmse[i]);
  }
  if (!std::isfinite(best))
    throw std::invalid_argument("no polynomial degree is increasing up to the highest bias of the experiments");
  for (size_t i = 0; i < fit.candidates.size() && choice.terms == 0; ++i)
    if (choice.mean_nrmse[i] <= (1.0 + o.parsimony) * best) choice.terms = static_cast<int>(i) + 1;
  std::ostringstream os;
  os << "smallest n whose mean held-out NRMSE is within " << 100.0 * o.parsimony << "% of the best (";
  for (size_t i = 0; i < choice.mean_nrmse.size(); ++i)
    os << (i ? ", " : "") << "n = " << i + 1 << ": "
       << (std::isnan(choice.mean_nrmse[i]) ? std::string("excluded, f turns over below the highest bias")
                                             : format("%.4g", choice.mean_nrmse[i]));
  os << ")";
  if (const auto turn = turnover(fit.candidate(choice.terms), o.amplifier_max_V)) {
    choice.voltage_max_V = std::floor((1.0 - o.turnover_margin) * *turn);
    os << format("; f turns over at %.1f V, so the voltage limit is %.0f V", *turn, *choice.voltage_max_V);
  }
  choice.rule = os.str();
  return choice;
}

}  // namespace pvcgel::control::identification
