#include "tools/text_output.hpp"

#include <cmath>
#include <ctime>
#include <fstream>
#include <stdexcept>

namespace pvcgel::tools {

std::string number_or_null(double value, const char* printf_format) {
  return std::isfinite(value) ? format(printf_format, value) : "null";
}

std::string toml_array(const std::vector<double>& values) {
  std::string s = "[";
  for (size_t i = 0; i < values.size(); ++i) s += (i ? ", " : "") + format("%.10g", values[i]);
  return s + "]";
}

void write_text_file(const std::filesystem::path& path, const std::string& text) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write " + path.string());
  f << text;
  if (!f.flush()) throw std::runtime_error("write failed: " + path.string());
}

void write_checked_toml(const std::filesystem::path& path, const std::string& text,
                        const std::function<void(const toml::table&, const std::string& path)>& check,
                        const std::string& refusal) {
  try {
    check(toml::parse(text), path.string());
  } catch (const std::exception& e) {
    throw std::runtime_error(refusal + ": " + e.what());
  }
  write_text_file(path, text);
}

double process_cpu_s() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

}  // namespace pvcgel::tools
