#pragma once
// Internal to meshing/: the number format and small helpers every mesh writer shares, so that
// the same mesh always gives the same bytes (shortest round-trip form of each double).

#include "core/file_io.h"
#include "core/geometry.h"

#include <Eigen/Core>

#include <charconv>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace organsmith::export_text {

inline std::string num(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v == 0.0 ? 0.0 : v);  // no "-0"
  return std::string(buf, r.ptr);
}

inline Eigen::Vector3d out_point(const Eigen::Vector3d& p, bool ras) { return ras ? lps_to_ras(p) : p; }

/// Writes `bytes` to `path` atomically.
inline void write_atomic(const std::filesystem::path& path, const std::string& bytes) { write_file_atomic(path, bytes); }

template <class T>
void put(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));  // x86-64 and aarch64 are little-endian, as STL and PLY require
  s.append(b, sizeof(T));
}

inline std::string xml_escape(const std::string& in) {
  std::string o;
  for (char c : in) {
    switch (c) {
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '&': o += "&amp;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

inline std::string vtk_points(const std::vector<Eigen::Vector3d>& pts, bool ras) {
  std::string s = "      <Points>\n        <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (const auto& v : pts) {
    const Eigen::Vector3d p = out_point(v, ras);
    s += "          " + num(p.x()) + " " + num(p.y()) + " " + num(p.z()) + "\n";
  }
  return s + "        </DataArray>\n      </Points>\n";
}

}  // namespace organsmith::export_text
