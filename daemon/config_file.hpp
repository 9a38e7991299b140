#pragma once
/// @file
/// Reading a TOML configuration or model file: the one place that turns a
/// missing, unreadable or malformed file into a ConfigError naming the file and
/// the line, for pvcgeld and every `pvcgel` subcommand alike (exit code 2).

#include <toml++/toml.h>

#include <string>

namespace pvcgel::daemon {

/// A parsed file and its text (for a hash of exactly what was read).
struct ConfigFile {
  toml::table root;
  std::string text;
};

/// Reads and parses `path`. @throws control::ConfigError keyed by `option` (the command-line
/// option that named the file, e.g. "--config") when the path is a directory,
/// cannot be read, or is not valid TOML (with `path:line:column`).
ConfigFile read_config_file(const std::string& path, const std::string& option);

}  // namespace pvcgel::daemon
