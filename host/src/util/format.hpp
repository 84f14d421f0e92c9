// Number formatting for messages.
#pragma once

#include <cstdio>
#include <string>

namespace corofem::detail {

/// Two significant digits in scientific notation, e.g. "3.2e-02": residuals and energies in messages.
inline std::string sci(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1e", value);
  return buffer;
}

}  // namespace corofem::detail
