#pragma once
/// @file
/// `pvcgel serve`: live view of the rigs on a DDS domain, in the browser and in Foxglove.

#include <CLI/CLI.hpp>

namespace pvcgel::tools {

void add_serve_command(CLI::App& app);

}  // namespace pvcgel::tools
