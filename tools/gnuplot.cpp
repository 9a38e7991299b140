#include "tools/gnuplot.hpp"

#include <cstdlib>
#include <stdexcept>

namespace pvcgel::tools {

void run_gnuplot(const std::filesystem::path& script) {
  if (std::system("command -v gnuplot >/dev/null 2>&1") != 0)
    throw std::runtime_error("gnuplot not found: install it (apt-get install gnuplot-nox) to get plots");
  const std::string cmd = "gnuplot '" + script.string() + "' 2>&1";
  if (std::system(cmd.c_str()) != 0)
    throw std::runtime_error("gnuplot failed on " + script.string());
}

}  // namespace pvcgel::tools
