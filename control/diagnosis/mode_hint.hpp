#pragma once
/// @file
/// Where a lightly damped structural mode hides (internal): the peaks of the model-error transfer
/// function, the residual's spectrum over the prediction's, estimated on the fit segment. A mode with a
/// damping ratio of 0.015 is 3% wide in frequency; the resonance candidate's coarse grid (an octave apart)
/// and its fit from there miss it beside another effect that dominates the residual.

#include <vector>

#include "control/diagnosis/diagnosis.hpp"

namespace pvcgel::control::diagnosis::detail {

/// The frequencies (Hz, at most `count`, strongest first) in [f_min_Hz, f_max_Hz] where the residual
/// y - yhat carries power above the noise `sigma_um` that is a multiple of the prediction's at the same
/// frequency, a narrow peak of |r(f)|^2 / |yhat(f)|^2 of at least 0.5: each contiguous fit range of each recording is
/// Hann-windowed and transformed, and the powers are pooled on a log-frequency grid 1% apart.
/// The prediction's power in the ratio is guarded by ten times the noise's, so a mode rung by little input
/// (a tone's leakage, a step) still shows while cells of noise alone do not. Empty when nothing stands out.
std::vector<double> mode_frequency_hints(const std::vector<Series>& data, const std::vector<std::vector<double>>& yhat,
                                         const std::vector<std::vector<char>>& held_out, double sigma_um,
                                         double f_min_Hz, double f_max_Hz, size_t count);

}  // namespace pvcgel::control::diagnosis::detail
