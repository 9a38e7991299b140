#pragma once
/// @file
/// `pvcgel record`: lossless telemetry recording over DDS.

#include <CLI/CLI.hpp>

namespace pvcgel::tools {

/// Adds `record` to the app.
void add_record_command(CLI::App& app);

}  // namespace pvcgel::tools
