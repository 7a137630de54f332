#pragma once
// Numbers in messages and text outputs: one formatting rule for the whole project.

#include <charconv>
#include <cstdio>
#include <string>

namespace organsmith {

/// `v` with at most `significant` significant digits, as printf's %g (no trailing zeros; the
/// same text as an ostream with precision(significant)).
inline std::string format_g(double v, int significant = 6) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", significant, v);
  return buf;
}

/// `v` with exactly `decimals` digits after the point, as printf's %.Nf.
inline std::string format_fixed(double v, int decimals = 2) {
  char buf[352];  // %.Nf of the largest double has 309 digits before the point
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return buf;
}

/// The shortest text that reads back as the same double (files meant to be read by programs:
/// meshes, VTK arrays); zero is written "0", never "-0".
inline std::string format_shortest(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v == 0.0 ? 0.0 : v);
  return std::string(buf, r.ptr);
}

}  // namespace organsmith
