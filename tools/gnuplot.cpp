#include "tools/gnuplot.hpp"

#include <cstdlib>
#include <string>
#include <system_error>
#include <vector>
#include <stdexcept>

namespace pvcgel::tools {

void run_gnuplot(const std::filesystem::path& script) {
  if (std::system("command -v gnuplot >/dev/null 2>&1") != 0)
    throw std::runtime_error("gnuplot not found: install it (apt-get install gnuplot-nox) to get plots");
  const std::string cmd = "gnuplot '" + script.string() + "' 2>&1";
  if (std::system(cmd.c_str()) != 0)
    throw std::runtime_error("gnuplot failed on " + script.string());
}

ScratchDirectory::ScratchDirectory(const std::string& prefix) {
  std::string pattern = (std::filesystem::temp_directory_path() / (prefix + "-XXXXXX")).string();
  std::vector<char> buf(pattern.begin(), pattern.end());
  buf.push_back('\0');
  if (!mkdtemp(buf.data())) throw std::runtime_error("cannot create a temporary directory like " + pattern);
  path_ = buf.data();
}

ScratchDirectory::~ScratchDirectory() {
  std::error_code ignored;  // best effort: a leftover temp directory is no reason to fail
  std::filesystem::remove_all(path_, ignored);
}

}  // namespace pvcgel::tools
