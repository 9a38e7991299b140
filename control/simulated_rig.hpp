#pragma once
/// @file
/// A simulated PVC gel rig that differs from the controller's model the way a
/// real one does. The HAL's `sim` backend wraps it.

#include <array>
#include <cstdint>
#include <optional>
#include <random>
#include <vector>

#include "control/effect.hpp"
#include "control/hammerstein_model.hpp"
#include "control/lti_filter.hpp"

namespace pvcgel::control {

/// Physical effects of the truth plant, each switchable. Defaults are the
/// "paper rig": the n = 3 nonlinearity (the controllers use n = 2), eq. (11),
/// one sample of I/O delay, laser noise and quantisation, mild hysteresis and
/// slow creep.
struct SimRigConfig {
  HammersteinModel truth = paper_model(3);
  double sample_time_s = 1e-3;
  int io_delay_samples = 1;  ///< whole samples between a command and the amplifier output
  double noise_sigma_um = 0.05;
  double quantization_um = 0.01;
  std::uint64_t seed = 1;

  /// Rate-independent Bouc-Wen hysteresis in the effective voltage the gel
  /// sees: x = u - alpha h, dh = du - (|du| h + du |h|) / (2 h_sat).
  /// h lags u and saturates at h_sat, so the effective voltage lags on
  /// reversals by up to alpha h_sat (volts).
  struct Hysteresis {
    bool enabled = true;
    double alpha = 0.05;
    double saturation_V = 30.0;  ///< h_sat
  } hysteresis;

  /// Slow viscoelastic creep: an extra first-order mode in parallel with G,
  /// `fraction G(0) / (tau s + 1)`, so a step settles `fraction` further over tau.
  struct Creep {
    bool enabled = true;
    double fraction = 0.02;
    double time_constant_s = 20.0;
  } creep;

  /// Effects diagnosed by `pvcgel diagnose` (`[[sim.truth.effect]]`, dominant
  /// first, at most kMaxEffects): the truth then runs as
  /// AugmentedPlant (model plus these effects) and the built-in
  /// hysteresis and creep must be off. A drift that wanders draws its random
  /// walk here (from `seed`), restarted at zero by every reset.
  std::vector<Effect> added_effects{};

  /// This rig with `truth` as its plant and every effect beyond the Hammerstein
  /// model switched off (no hysteresis, creep, noise or quantisation; the I/O
  /// delay and sample time stay): a rig that is exactly a model.
  [[nodiscard]] SimRigConfig exactly(const HammersteinModel& model) const {
    SimRigConfig c = *this;
    c.truth = model;
    c.hysteresis.enabled = c.creep.enabled = false;
    c.added_effects.clear();
    c.noise_sigma_um = c.quantization_um = 0.0;
    return c;
  }
};

/// One simulated actuator with its laser sensor and amplifier. Deterministic
/// for a given seed. Cycle convention (the daemon's): `measure()` returns the
/// displacement at the start of cycle k, then `apply(u)` sets the command for
/// cycle k and advances time by one sample.
class SimulatedRig final {
 public:
  /// @throws ConfigError on invalid parameters.
  explicit SimulatedRig(const SimRigConfig& config);

  /// Laser reading at the start of this cycle (noise and quantisation included).
  double measure() noexcept;
  /// Command the amplifier for this cycle and advance one sample.
  void apply(double voltage_V) noexcept;
  /// True displacement now, without sensor effects.
  [[nodiscard]] double true_displacement_um() const noexcept { return y_true_; }
  /// Put the rig at rest under a constant voltage (hysteresis state virgin).
  void reset_steady_state(double voltage_V) noexcept;
  /// Voltage above which the truth's polynomial turns over; it is held flat there
  /// (stroke saturation), since a real gel does not reverse.
  [[nodiscard]] double saturation_voltage_V() const noexcept { return x_sat_; }
  [[nodiscard]] const SimRigConfig& config() const noexcept { return cfg_; }

 private:
  [[nodiscard]] double static_output(double x_V) const noexcept;

  static constexpr int kMaxDelay = 16;
  SimRigConfig cfg_;
  LtiFilter G_, creep_;
  std::array<double, kMaxDelay> delay_line_{};
  int delay_head_ = 0;
  double x_sat_ = 1000.0;
  double u_prev_ = 0.0, h_ = 0.0;
  double y_true_ = 0.0;
  double wander_step_um_ = 0.0;  ///< a wandering drift's RMS step per sample (0: none)
  double wander_um_ = 0.0;       ///< its random walk since the last reset
  std::optional<AugmentedPlant> augmented_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> noise_{0.0, 1.0};
};

}  // namespace pvcgel::control
