#pragma once
/// @file
/// `pvcgel status|watch|arm|start|stop|reset|mode|target|clear|send`: drive a
/// running pvcgeld over DDS.

#include <CLI/CLI.hpp>

namespace pvcgel::tools {

/// Exit codes of the client subcommands (besides 0 and 1).
inline constexpr int kExitNoDaemon = 3;  ///< no daemon / rig unknown
inline constexpr int kExitRejected = 4;  ///< the daemon refused the command or chunk

/// Adds the client subcommands to the app.
void add_client_commands(CLI::App& app);

}  // namespace pvcgel::tools
