#pragma once
/// @file
/// The recording the diagnosis tests share: a 20 s multisine around 350 V through the paper's n = 3 model.

#include <cmath>
#include <cstdint>
#include <random>
#include <span>

#include "control/diagnosis/diagnosis.hpp"

namespace pvcgel::control::diagnosis::testing_rig {

inline constexpr double Ts = 1e-3;

/// A 20 s multisine recording of `model` with `effect`, white noise sigma.
inline Series recording(const Effect& effect, double sigma, std::uint64_t seed = 3, double seconds = 20.0) {
  Series s;
  s.sample_time_s = Ts;
  const auto n = static_cast<size_t>(seconds / Ts);
  for (size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * Ts;
    s.t_s.push_back(t);
    s.u_V.push_back(350.0 + 120.0 * std::sin(2 * M_PI * 0.3 * t) + 60.0 * std::sin(2 * M_PI * 1.7 * t + 1.0) +
                    30.0 * std::sin(2 * M_PI * 4.1 * t + 2.0));
  }
  AugmentedPlant p(paper_model(3), 1, Ts, effect);
  s.y_um = p.simulate(s.u_V, s.u_V[0]);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> N(0.0, sigma);
  for (double& y : s.y_um) y += N(rng);
  return s;
}

}  // namespace pvcgel::control::diagnosis::testing_rig
