#pragma once
/// @file
/// Formatting and file writing shared by the `pvcgel` subcommands: one copy of
/// each, so every report, model file and message prints numbers the same way.

#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <toml++/toml.h>

#include "control/text_format.hpp"

namespace pvcgel::tools {

using control::format;

/// `printf_format` applied, or `null` (JSON's word for it) when the value is not finite.
std::string number_or_null(double value, const char* printf_format = "%.6g");

/// A TOML array of numbers with 10 significant digits: `[0.127, 1.3057e-05]`.
std::string toml_array(const std::vector<double>& values);

/// Writes `text` to `path`, creating its parent directories.
/// @throws std::runtime_error naming the path when it cannot be written.
void write_text_file(const std::filesystem::path& path, const std::string& text);

/// Writes a TOML file this program made only if it loads where it is meant to:
/// `check` gets the parsed text and throws (e.g. the daemon's configuration
/// parser) when it does not. @throws std::runtime_error "`refusal`: <why>", and
/// then nothing is written.
void write_checked_toml(const std::filesystem::path& path, const std::string& text,
                        const std::function<void(const toml::table&, const std::string& path)>& check,
                        const std::string& refusal);

/// CPU time of this process in seconds (what speed targets are about, not wall time).
double process_cpu_s();

}  // namespace pvcgel::tools
