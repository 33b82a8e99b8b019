// Short text for a float in the client passes' parameter errors ("%g": 0.5, 1e-05).
#pragma once

#include <cstdio>
#include <string>

namespace irradcast {

inline std::string float_text(float v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", static_cast<double>(v));
  return buf;
}

}  // namespace irradcast
