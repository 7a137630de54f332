#pragma once
// Contours, surface and tetrahedral meshes and polylines, all in LPS millimetres.

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace organsmith {

/// One closed planar contour on slice `slice_k` of a volume, points in LPS mm, in order.
struct Contour {
  std::int64_t slice_k = 0;
  std::vector<Eigen::Vector3d> points_lps_mm;
  bool closed = true;

  /// Perimeter in mm (includes the closing segment when `closed`).
  double length_mm() const;
};

/// The contours of one organ, one or more per slice, ordered by slice index.
struct ContourStack {
  std::string organ;
  std::vector<Contour> contours;
};

/// Triangle surface. Triangles are counter-clockwise seen from outside (normals point out).
struct SurfaceMesh {
  std::vector<Eigen::Vector3d> vertices_lps_mm;
  std::vector<std::array<std::int32_t, 3>> triangles;
  std::vector<std::int32_t> region_ids;  ///< per triangle; empty = one region

  /// Signed enclosed volume in mm³ (positive for a closed outward-oriented surface).
  double signed_volume_mm3() const;
  double area_mm2() const;
};

/// Tetrahedral mesh. Each tet (a, b, c, d) is positively oriented:
/// (b − a) · ((c − a) × (d − a)) > 0.
struct TetMesh {
  std::vector<Eigen::Vector3d> vertices_lps_mm;
  std::vector<std::array<std::int32_t, 4>> tets;
  std::vector<std::int32_t> region_ids;  ///< per tet, same length as `tets`

  /// Signed volume of tet t in mm³.
  double tet_volume_mm3(std::size_t t) const;
  double volume_mm3() const;
};

/// An open or closed polyline in LPS mm (guidance paths, centerlines).
struct Polyline {
  std::string name;
  std::vector<Eigen::Vector3d> points_lps_mm;
  bool closed = false;

  /// Cumulative arc length at each point, mm (first entry 0).
  std::vector<double> arc_length_mm() const;
  double length_mm() const;
};

}  // namespace organsmith
