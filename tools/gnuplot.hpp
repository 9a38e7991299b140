#pragma once
/// @file
/// Plots through gnuplot (Debian gnuplot-nox): data files plus a script, run once.

#include <filesystem>
#include <string>

namespace pvcgel::tools {

/// Runs `gnuplot script_path`. @throws std::runtime_error with an actionable
/// message when gnuplot is missing or fails.
void run_gnuplot(const std::filesystem::path& script_path);

}  // namespace pvcgel::tools
