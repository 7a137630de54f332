#pragma once
// Numbers in messages and text outputs: one formatting rule for the whole project.

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

}  // namespace organsmith
