#pragma once
/// @file
/// Amplitude and phase of the fundamental (plus DC and harmonics) of a sine
/// experiment, from the sampled input and output alone.

#include <complex>
#include <string>
#include <vector>

namespace pvcgel::control::identification {

/// The sinusoid found in a sampled input: `u = B + A sin(2 pi f t + phase)`.
struct SineEstimate {
  double amplitude_V = 0.0;
  double bias_V = 0.0;
  double frequency_Hz = 0.0;
  double phase_rad = 0.0;        ///< at t = t_s[0] of the samples fitted
  double residual_rms_V = 0.0;   ///< what the sinusoid does not explain
  bool found = false;            ///< false: no oscillation (fewer than 4 crossings)
};

/// Four-parameter least-squares sine fit (IEEE 1057): a coarse frequency from
/// mean-level crossings, refined by Gauss-Newton on (B, a, b, omega).
SineEstimate estimate_sine(const std::vector<double>& t_s, const std::vector<double>& u_V, size_t begin,
                           size_t end);

/// Settings of the extraction.
struct ExtractionOptions {
  double settle_s = 10.0;            ///< samples before t_s[0] + settle_s are not analysed
  int min_periods = 3;               ///< fewer whole periods after settling: flagged, excluded
  int harmonics = 5;                 ///< harmonics 1..harmonics are fitted and reported
  double max_input_distortion = 0.005;  ///< sine-fit residual rms / A above this: flagged
  double voltage_min_V = 0.0;        ///< amplifier limits, to name clipping in messages
  double voltage_max_V = 1000.0;
};

/// Frequency response of one sine experiment at its excitation frequency.
struct FrequencyResponsePoint {
  std::string source;            ///< file or experiment label, for messages
  double amplitude_V = 0.0;      ///< A, estimated from u
  double bias_V = 0.0;           ///< B, estimated from u
  double frequency_Hz = 0.0;     ///< f, estimated from u
  /// Y1 / U1 of the sampled sequences (um/V): includes the rig's I/O delay and
  /// the zero-order hold exactly as the loop sees them.
  std::complex<double> response{0.0, 0.0};
  /// Standard uncertainty of `response` (um/V): spread of the per-period
  /// estimates / sqrt(periods).
  double response_sigma = 0.0;
  double dc_um = 0.0;                   ///< mean displacement over the analysed periods
  double drift_um_per_s = 0.0;          ///< linear trend fitted alongside (creep, thermal drift)
  std::vector<double> harmonic_um;      ///< |Y_k|, k = 1..harmonics (index 0 is the fundamental)
  double input_distortion = 0.0;        ///< sine-fit residual rms of u / A
  int periods = 0;                      ///< whole periods analysed
  double window_start_s = 0.0;          ///< analysed window, relative to the first sample
  double window_end_s = 0.0;
  bool valid = false;                   ///< false: flagged, excluded from every fit
  std::string problem;                  ///< why it was flagged

  [[nodiscard]] double omega_rad_s() const noexcept;
  /// |Y1| / |U1|.
  [[nodiscard]] double gain() const noexcept { return std::abs(response); }
};

/// Extracts the fundamental of y at the frequency of u by linear least squares
/// on [1, t, cos(k w t), sin(k w t), k = 1..H] over the last whole periods after
/// the settling time (a lock-in that tolerates a non-integer number of samples
/// per period and a slow drift). Never throws on bad data: the point comes back
/// `valid = false` with the reason (too few periods, clipped or distorted
/// input, no oscillation, non-finite samples).
/// @param t_s  uniformly sampled times (checked by the caller, e.g. the recording reader)
FrequencyResponsePoint extract_frequency_response(const std::vector<double>& t_s, const std::vector<double>& u_V,
                                                  const std::vector<double>& y_um, const ExtractionOptions& options,
                                                  std::string source = {});

}  // namespace pvcgel::control::identification
