#pragma once
/// @file
/// Choosing the degree n of f by what matters to a user of the model: how well
/// it predicts held-out time responses, not how small its frequency-domain
/// residual is. A degree whose f turns over inside the amplifier's range is
/// usable together with a voltage limit below the turnover, never silently.

#include <optional>
#include <string>
#include <vector>

#include "control/identification/nonlinearity_fit.hpp"
#include "control/identification/sine_experiment.hpp"

namespace pvcgel::control::identification {

/// The degree to use and the voltage limit it needs.
struct ModelChoice {
  int terms = 0;                         ///< n
  std::optional<double> voltage_max_V;   ///< set when f turns over below the amplifier's maximum
  std::string rule;                      ///< the rule applied, in words, with the numbers
  std::vector<double> mean_nrmse;        ///< per n (index n - 1): mean held-out NRMSE; NaN if not admissible
};

/// Settings of choose_by_validation.
struct ModelChoiceOptions {
  double amplifier_max_V = 1000.0;   ///< the range the inverse must cover without a limit
  double highest_bias_V = 0.0;       ///< a turnover below this operating point cannot serve it
  double parsimony = 0.05;           ///< a smaller n within this fraction of the best NRMSE wins
  double turnover_margin = 0.02;     ///< the limit sits this fraction below the turnover
};

/// Picks n by the mean held-out NRMSE over `metrics[record][n - 1]`, among the
/// candidates whose f increases at 0 and does not turn over below the highest
/// bias (operating point) the experiments were made at: peaks beyond a
/// turnover are where the actuator holds flat, which a polynomial follows only
/// up to its turnover. If the chosen f turns over below `amplifier_max_V`, the
/// choice carries a voltage limit just below it.
/// @throws std::invalid_argument when no candidate is admissible or metrics are missing.
ModelChoice choose_by_validation(const NonlinearityFit& fit, const std::vector<std::vector<PredictionMetrics>>& metrics,
                                 const ModelChoiceOptions& options);

}  // namespace pvcgel::control::identification
