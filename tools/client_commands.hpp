#pragma once
/// @file
/// `pvcgel status|watch|arm|start|stop|reset|mode|target|clear|send`: drive a
/// running pvcgeld over DDS.

#include <CLI/CLI.hpp>

#include "tools/exit_codes.hpp"

namespace pvcgel::tools {

/// Adds the client subcommands to the app.
void add_client_commands(CLI::App& app);

}  // namespace pvcgel::tools
