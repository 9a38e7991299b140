#pragma once
/// @file
/// Parsing of the TOML configuration tables (`[model]`, `[controller]`, `[sim]`)
/// into validated structures. Pure: the caller reads the file.

#include <toml++/toml.h>

#include "control/controller.hpp"
#include "control/simulated_rig.hpp"

namespace pvcgel::control {

/// A parsed configuration file. Tables that are absent keep their defaults.
struct RigConfiguration {
  HammersteinModel model = paper_model(2);  ///< `[model]`: what the controller believes
  ControllerConfig controller{};            ///< `[controller]`, plus `[model] io_delay_samples` and `[[model.effect]]`
  SimRigConfig sim{};                       ///< `[sim]`: the simulated truth
};

/// Parses and validates. Every key is checked: unknown keys, wrong types and
/// unsafe values raise ConfigError naming the dotted key; the controller and
/// the simulated rig are built once to run their own checks (monotone inverse,
/// proper Q G^-1, closed-loop stability, ...).
/// @param source  file name for messages
/// @param other_tables  top-level tables the caller parses itself (not unknown)
RigConfiguration parse_configuration(const toml::table& root, const std::string& source,
                                     const std::vector<std::string>& other_tables = {});

/// Reads only `[sim]` (and `[controller] period_s`, its sample time) and builds
/// the simulated rig once: what the sim backend needs, without designing a
/// controller (a diagnosed model need not have a tunable one). Other tables are ignored.
SimRigConfig parse_simulated_rig(const toml::table& root, const std::string& source);

/// Reads only a `[model]` table (identification output, or a full config).
HammersteinModel parse_model(const toml::table& root, const std::string& source);

}  // namespace pvcgel::control
