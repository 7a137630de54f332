// Per-element material axes of an organ wall (see material_axes.h).

#include "meshing/material_axes.h"

#include <Eigen/Eigenvalues>

#include <cmath>
#include <limits>
#include <unordered_map>

namespace organsmith {

std::vector<MaterialAxes> wall_material_axes(const SolverModel& m, std::int32_t region_id) {
  const auto outer = m.surfaces.find(m.organ + "_outer");
  if (outer == m.surfaces.end() || outer->second.empty() || m.nodes_lps_mm.empty()) return {};

  // Principal axes of the organ's nodes.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : m.nodes_lps_mm) mean += p;
  mean /= double(m.nodes_lps_mm.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : m.nodes_lps_mm) cov += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  const Eigen::Vector3d major = eig.eigenvectors().col(2), second = eig.eigenvectors().col(1);

  // Outer faces in a uniform grid of their centroids, for the nearest face of each element.
  struct Face {
    Eigen::Vector3d centroid, normal;
  };
  std::vector<Face> faces;
  for (const auto& f : outer->second) {
    const auto n = m.face_nodes(f);
    const Eigen::Vector3d c = (m.nodes_lps_mm[n[0]] + m.nodes_lps_mm[n[1]] + m.nodes_lps_mm[n[2]]) / 3.0;
    const Eigen::Vector3d a = m.face_area_out_mm2(f);
    if (a.norm() > 0) faces.push_back({c, a.normalized()});
  }
  if (faces.empty()) return {};
  const double cell_mm = 4.0;
  auto key = [&](const Eigen::Vector3d& p, int dx = 0, int dy = 0, int dz = 0) {
    const auto i = std::int64_t(std::floor(p.x() / cell_mm)) + dx, j = std::int64_t(std::floor(p.y() / cell_mm)) + dy,
               k = std::int64_t(std::floor(p.z() / cell_mm)) + dz;
    return (i * 73856093) ^ (j * 19349663) ^ (k * 83492791);
  };
  std::unordered_map<std::int64_t, std::vector<std::size_t>> grid;
  for (std::size_t i = 0; i < faces.size(); ++i) grid[key(faces[i].centroid)].push_back(i);

  std::vector<MaterialAxes> axes;
  for (std::size_t e = 0; e < m.elements.size(); ++e) {
    if (m.region_ids[e] != region_id) continue;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) c += m.nodes_lps_mm[m.elements[e][k]];
    c /= 4.0;
    // Nearest outer face: grid shells of growing radius until one holds a face, then one more
    // shell (a nearer face may sit in the next shell's corner).
    std::size_t best = 0;
    double best_d = std::numeric_limits<double>::infinity();
    int found_at = -1;
    for (int r = 0; r < 64 && (found_at < 0 || r <= found_at + 1); ++r) {
      for (int dx = -r; dx <= r; ++dx)
        for (int dy = -r; dy <= r; ++dy)
          for (int dz = -r; dz <= r; ++dz) {
            if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;
            const auto it = grid.find(key(c, dx, dy, dz));
            if (it == grid.end()) continue;
            for (std::size_t i : it->second)
              if (const double d = (faces[i].centroid - c).squaredNorm(); d < best_d) best_d = d, best = i;
          }
      if (found_at < 0 && std::isfinite(best_d)) found_at = r;
    }
    if (!std::isfinite(best_d)) {  // the grid search gave up (a far-flung element): scan all
      for (std::size_t i = 0; i < faces.size(); ++i)
        if (const double d = (faces[i].centroid - c).squaredNorm(); d < best_d) best_d = d, best = i;
    }
    const Eigen::Vector3d n = faces[best].normal;
    Eigen::Vector3d l = major - major.dot(n) * n;
    if (l.norm() < 0.25) l = second - second.dot(n) * n;
    l.normalize();
    axes.push_back({l, n.cross(l).normalized()});
  }
  return axes;
}

}  // namespace organsmith
