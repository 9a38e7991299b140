#pragma once
/// @file
/// printf-style formatting into a string: the one copy used by configuration
/// messages here and by every `pvcgel` report, so numbers print the same way
/// everywhere (`%g`, never a 300-digit `std::to_string` of a huge double).
/// Configuration time only: it allocates.

#include <cstdio>
#include <string>

namespace pvcgel::control {

/// `printf_format` applied to `values` (at most 511 characters).
template <typename... Args>
std::string format(const char* printf_format, Args... values) {
  char buf[512];
  std::snprintf(buf, sizeof buf, printf_format, values...);
  return buf;
}

}  // namespace pvcgel::control
