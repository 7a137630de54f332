#pragma once
// Internal to meshing/: the number format and small helpers every mesh writer shares, so that
// the same mesh always gives the same bytes (shortest round-trip form of each double).

#include "core/file_io.h"
#include "core/format.h"
#include "core/vtk_xml.h"
#include "core/geometry.h"

#include <Eigen/Core>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace organsmith::export_text {

inline std::string num(double v) { return format_shortest(v); }

inline Eigen::Vector3d out_point(const Eigen::Vector3d& p, bool ras) { return ras ? lps_to_ras(p) : p; }

/// Writes `bytes` to `path` atomically.
inline void write_atomic(const std::filesystem::path& path, const std::string& bytes) { write_file_atomic(path, bytes); }

template <class T>
void put(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));  // x86-64 and aarch64 are little-endian, as STL and PLY require
  s.append(b, sizeof(T));
}

using organsmith::xml_escape;

}  // namespace organsmith::export_text
