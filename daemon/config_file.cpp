#include "daemon/config_file.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "control/config_error.hpp"

namespace pvcgel::daemon {

ConfigFile read_config_file(const std::string& path, const std::string& option) {
  using control::ConfigError;
  if (std::filesystem::is_directory(path))
    throw ConfigError(option, "'" + path + "' is a directory, not a configuration file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(option, "cannot read configuration file '" + path + "'");
  std::stringstream buffer;
  buffer << in.rdbuf();
  ConfigFile file{{}, buffer.str()};
  try {
    file.root = toml::parse(file.text, path);
    return file;
  } catch (const toml::parse_error& e) {
    std::ostringstream os;
    os << path << ":" << e.source().begin.line << ":" << e.source().begin.column << ": not valid TOML: "
       << e.description();
    throw ConfigError(option, os.str());
  }
}

}  // namespace pvcgel::daemon
