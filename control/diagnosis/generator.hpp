#pragma once
/// @file
/// Recordings with a concealed effect, for scoring `pvcgel diagnose` blind.
///
/// The generator deliberately does not share the candidates' code path or
/// parameterisation (effect.hpp): hysteresis, the baseline and delay run on
/// SimulatedRig (Bouc-Wen, whole-sample delay line); every other effect runs
/// on a continuous-time truth integrated with RK4 (the candidates use exact
/// ZOH discretisations) with its own form of the effect:
///  - creep: two Kelvin-Voigt elements (tau and 5 tau, 60/40 split);
///  - dead_zone: smooth threshold x = u (1 - exp(-(u/d)^4));
///  - saturation: y -> tanh(s y) / s;
///  - asymmetric_dynamics: time scale 1 + m (1 + tanh(e / 0.2 um)) / 2, e = y - G(0) w;
///  - slew_limit: the amplifier voltage ramps continuously at S toward each new
///    command inside the sample (the candidate holds one value per sample);
///  - resonance: the measured output follows the gel through a mode
///    q'' = w_n^2 (y - q) - 2 zeta w_n q' (output side; the candidate's mode is on the input side);
///  - drift: m (1 - exp(-(t - t0) / tau_d)) after an onset t0;
///  - bias_dependent_dynamics: time scale 1 + m ybar / 100 um, ybar the displacement low-passed over 0.5 s.

#include <cstdint>
#include <string>
#include <vector>

#include "control/diagnosis/diagnosis.hpp"

namespace pvcgel::control::diagnosis {

/// How cases are generated.
struct GeneratorOptions {
  double duration_s = 30.0;
  double sample_time_s = 1e-3;
  int io_delay_samples = 1;
  double noise_sigma_um = 0.05;
  double quantization_um = 0.01;
  double effect_rms_min = 3.0;  ///< target effect RMS on the held-out samples (held_out_mask), in noise sigmas
  double effect_rms_max = 6.0;
  double closed_loop_probability = 0.3;
};

/// What was generated (kept apart from the recordings: the diagnosis never sees it).
struct GroundTruth {
  EffectKind effect = EffectKind::none;
  double magnitude = 0.0;           ///< the generator's own magnitude parameter
  double effect_rms_um = 0.0;       ///< RMS of (true output - nominal model) on the held-out samples
  double effect_peak_um = 0.0;      ///< largest |true output - nominal model|
  double stroke_um = 0.0;
  bool closed_loop = false;
  bool within_spec = false;         ///< effect RMS near the target and peak under 1% of the stroke (else the best of 12 draws)
  std::string input;                ///< a description of the excitation
};

/// One blind case.
struct GeneratedCase {
  std::vector<Series> recordings;
  GroundTruth truth;
};

/// Generates one recording of `model` with `effect` concealed. Deterministic in seed.
GeneratedCase generate_case(const HammersteinModel& model, EffectKind effect, std::uint64_t seed,
                            const GeneratorOptions& options = {});

/// A suite plan: `cases` labels covering every effect and none as evenly as
/// possible, shuffled with `seed`, each with its own case seed.
std::vector<std::pair<EffectKind, std::uint64_t>> blind_suite_plan(int cases, std::uint64_t seed);

}  // namespace pvcgel::control::diagnosis
