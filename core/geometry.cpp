#include "core/geometry.h"

#include <Eigen/Geometry>

namespace organsmith {

double Contour::length_mm() const {
  const auto n = points_lps_mm.size();
  if (n < 2) return 0.0;
  double len = 0.0;
  for (std::size_t a = 1; a < n; ++a) len += (points_lps_mm[a] - points_lps_mm[a - 1]).norm();
  if (closed) len += (points_lps_mm.front() - points_lps_mm.back()).norm();
  return len;
}

double SurfaceMesh::signed_volume_mm3() const {
  double six_v = 0.0;
  for (const auto& t : triangles) {
    six_v += vertices_lps_mm[t[0]].dot(vertices_lps_mm[t[1]].cross(vertices_lps_mm[t[2]]));
  }
  return six_v / 6.0;
}

double SurfaceMesh::area_mm2() const {
  double a = 0.0;
  for (const auto& t : triangles) {
    a += 0.5 * (vertices_lps_mm[t[1]] - vertices_lps_mm[t[0]])
                   .cross(vertices_lps_mm[t[2]] - vertices_lps_mm[t[0]])
                   .norm();
  }
  return a;
}

double TetMesh::tet_volume_mm3(std::size_t t) const {
  const auto& c = tets[t];
  const Eigen::Vector3d& a = vertices_lps_mm[c[0]];
  return (vertices_lps_mm[c[1]] - a).dot((vertices_lps_mm[c[2]] - a).cross(vertices_lps_mm[c[3]] - a)) /
         6.0;
}

double TetMesh::volume_mm3() const {
  double v = 0.0;
  for (std::size_t t = 0; t < tets.size(); ++t) v += tet_volume_mm3(t);
  return v;
}

std::vector<double> Polyline::arc_length_mm() const {
  std::vector<double> s(points_lps_mm.size(), 0.0);
  for (std::size_t a = 1; a < points_lps_mm.size(); ++a)
    s[a] = s[a - 1] + (points_lps_mm[a] - points_lps_mm[a - 1]).norm();
  return s;
}

double Polyline::length_mm() const {
  if (points_lps_mm.size() < 2) return 0.0;
  double len = arc_length_mm().back();
  if (closed) len += (points_lps_mm.front() - points_lps_mm.back()).norm();
  return len;
}

}  // namespace organsmith
