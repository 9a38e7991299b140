#pragma once
/// @file
/// `pvcgel show REC.csv`: summary and plot of a recording.

#include <CLI/CLI.hpp>

namespace pvcgel::tools {

/// Adds `show` to the app.
void add_show_command(CLI::App& app);

}  // namespace pvcgel::tools
