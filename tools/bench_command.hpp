#pragma once
/// @file
/// `pvcgel bench ...` subcommands.

#include <CLI/CLI.hpp>

namespace pvcgel::tools {

/// Adds `bench` (with `paper`) to the app.
void add_bench_command(CLI::App& app);

}  // namespace pvcgel::tools
