#pragma once
/// @file
/// The whole describing-function identification (paper Section III): G(s)
/// from the reference regime, then f from every grid point.

#include <complex>
#include <string>
#include <vector>

#include "control/hammerstein_model.hpp"
#include "control/identification/frequency_response.hpp"
#include "control/identification/nonlinearity_fit.hpp"
#include "control/identification/transfer_function_fit.hpp"

namespace pvcgel::control::identification {

/// Settings of `identify`.
struct IdentificationOptions {
  TransferFunctionFitOptions G{};
  NonlinearityFitOptions f{};
  double reference_amplitude_V = 300.0;  ///< the paper: smallest amplitude tested
  double reference_bias_V = 450.0;       ///< the paper: median bias tested
  double regime_tolerance_V = 5.0;       ///< |A - A_ref| and |B - B_ref| within this: reference regime
  double sample_time_s = 1e-3;           ///< of the experiments
  int io_delay_samples = 1;              ///< the rig's I/O delay (a configured fact of the rig)
};

/// Normalisation of the model, stated wherever results are shown.
inline constexpr const char* kNormalisation =
    "G(s) is fitted to the response measured at the reference regime (A_ref, B_ref) with the sampling delays "
    "removed, i.e. N(A_ref, B_ref) = 1 by convention; f then carries the scale and is fitted to "
    "d = measured gain / |G(jw)| at every valid grid point. Only N(A,B) |G(jw)| and f(x) G(s) are unique: "
    "(c, G) and (k c, G / k) are the same model.";

/// Everything `identify` found.
struct IdentificationResult {
  std::vector<FrequencyResponsePoint> points;     ///< all points, flagged ones included
  std::vector<std::complex<double>> continuous;   ///< per point: response with ZOH and I/O delay removed
  std::vector<size_t> used;                       ///< indices of valid points (fit of f)
  std::vector<size_t> reference;                  ///< indices of the reference regime (fit of G)
  TransferFunctionFit G_fit;
  NonlinearityFit f_fit;

  /// f of candidate n with the fitted G.
  [[nodiscard]] HammersteinModel model(int n) const;
  /// The chosen model.
  [[nodiscard]] HammersteinModel chosen_model() const { return model(f_fit.chosen_terms); }
};

/// Removes what sampling adds to a measured discrete response: the zero-order
/// hold (e^{-j w Ts/2} sinc(w Ts/2)) and `io_delay_samples` whole samples.
/// What is left is G(jw) of the continuous plant (aliasing is negligible below
/// a tenth of the Nyquist frequency for the gel's roll-off).
std::complex<double> remove_sampling_delay(std::complex<double> response, double omega_rad_s, double sample_time_s,
                                           int io_delay_samples);

/// Overall describing-function gain of a model at a grid point: N(A, B) |G(jw)| (paper eq. (9)).
double overall_gain(const HammersteinModel& model, double amplitude_V, double bias_V, double omega_rad_s);

/// Runs both fits on extracted points. Flagged points are excluded (they stay
/// in `points` with their reason).
/// @throws std::invalid_argument when too few valid points remain, naming what is missing
///         (for instance no point at the reference regime).
IdentificationResult identify(std::vector<FrequencyResponsePoint> points, const IdentificationOptions& options);

}  // namespace pvcgel::control::identification
