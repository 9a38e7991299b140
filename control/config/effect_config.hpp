#pragma once
/// @file
/// Reading effects from a configuration file: one function for a list of
/// effect tables, shared by `[[sim.truth.effect]]` (the simulated rig) and
/// `[[model.effect]]` (what the controller compensates).
///
/// Format: an array of tables, dominant effect first, each with `name` and the
/// effect's physical parameters (units in the key names, see parameter_specs):
///
///     [[sim.truth.effect]]
///     name = "hysteresis"
///     alpha = 0.05
///     threshold_scale_V = 20.0
///     [[sim.truth.effect]]
///     name = "creep"
///     fraction = 0.02
///     time_constant_s = 5.0
///
/// A single table (`[sim.truth.effect]`, the format before mixtures) is read
/// as a list of one.

#include <string>
#include <vector>

#include "control/effect.hpp"
#include "control/config/toml_reader.hpp"

namespace pvcgel::control {

/// Reads the effect list under `key` of `parent` (empty when absent).
/// @throws ConfigError naming the key (e.g. "sim.truth.effect[1].alpha") for an
///         unknown name or key, a missing or out-of-range parameter, or a
///         combination the plant cannot run (validate_mixture).
std::vector<Effect> read_effect_tables(TableReader& parent, const std::string& key, double sample_time_s);

}  // namespace pvcgel::control
