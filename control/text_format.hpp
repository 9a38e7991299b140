#pragma once
/// @file
/// printf-style formatting and joining into a string: the one copy used by configuration
/// messages here and by every `pvcgel` report, so numbers print the same way
/// everywhere (`%g`, never a 300-digit `std::to_string` of a huge double).
/// Configuration time only: it allocates.

#include <cstdio>
#include <string>
#include <vector>

namespace pvcgel::control {

/// `printf_format` applied to `values`, however long (measured first, then written).
template <typename... Args>
std::string format(const char* printf_format, Args... values) {
  const int length = std::snprintf(nullptr, 0, printf_format, values...);
  if (length <= 0) return {};
  std::string out(static_cast<size_t>(length), '\0');
  std::snprintf(out.data(), out.size() + 1, printf_format, values...);
  return out;
}

/// `parts` with `separator` between them: "a, b, c".
inline std::string join(const std::vector<std::string>& parts, const std::string& separator) {
  std::string out;
  for (size_t i = 0; i < parts.size(); ++i) out += (i ? separator : std::string()) + parts[i];
  return out;
}

}  // namespace pvcgel::control
