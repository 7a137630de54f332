#include "core/grid.h"

#include "core/errors.h"

#include <Eigen/LU>

#include <cmath>
#include <sstream>

namespace organsmith {

Eigen::Vector3d ImageGrid::index_to_lps_mm(const Eigen::Vector3d& ijk) const {
  return origin_lps_mm + direction_lps * spacing_mm.cwiseProduct(ijk);
}

Eigen::Vector3d ImageGrid::lps_mm_to_index(const Eigen::Vector3d& p_lps_mm) const {
  // Direction may be non-orthogonal for sheared data read from files; solve rather than
  // transpose so the inverse stays exact.
  const Eigen::Vector3d scaled = direction_lps.partialPivLu().solve(p_lps_mm - origin_lps_mm);
  return scaled.cwiseQuotient(spacing_mm);
}

Eigen::Matrix4d ImageGrid::index_to_lps_affine() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = direction_lps * spacing_mm.asDiagonal();
  m.topRightCorner<3, 1>() = origin_lps_mm;
  return m;
}

Eigen::Matrix4d ImageGrid::index_to_ras_affine() const {
  Eigen::Matrix4d flip = Eigen::Matrix4d::Identity();
  flip(0, 0) = -1.0;
  flip(1, 1) = -1.0;
  return flip * index_to_lps_affine();
}

std::array<Eigen::Vector3d, 2> ImageGrid::bounds_lps_mm() const {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY);
  Eigen::Vector3d hi = Eigen::Vector3d::Constant(-INFINITY);
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d ijk((c & 1) ? double(size_vox[0] - 1) : 0.0,
                              (c & 2) ? double(size_vox[1] - 1) : 0.0,
                              (c & 4) ? double(size_vox[2] - 1) : 0.0);
    const Eigen::Vector3d p = index_to_lps_mm(ijk);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return {lo, hi};
}

bool ImageGrid::same_geometry(const ImageGrid& other, double tol_mm) const {
  if (size_vox != other.size_vox) return false;
  // Compare the physical positions of the corners: this catches spacing, origin and direction
  // differences in one figure with a physical unit.
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d ijk((c & 1) ? double(size_vox[0] - 1) : 0.0,
                              (c & 2) ? double(size_vox[1] - 1) : 0.0,
                              (c & 4) ? double(size_vox[2] - 1) : 0.0);
    if ((index_to_lps_mm(ijk) - other.index_to_lps_mm(ijk)).norm() > tol_mm) return false;
  }
  // Degenerate sizes (a single voxel along an axis) hide spacing differences: check them too.
  return (spacing_mm - other.spacing_mm).cwiseAbs().maxCoeff() <= tol_mm;
}

void ImageGrid::validate() const {
  std::ostringstream why;
  for (int a = 0; a < 3; ++a) {
    if (size_vox[a] <= 0) why << "size along axis " << a << " is " << size_vox[a] << "; ";
    if (!(spacing_mm[a] > 0.0) || !std::isfinite(spacing_mm[a]))
      why << "spacing along axis " << a << " is " << spacing_mm[a] << " mm; ";
  }
  const double ortho = (direction_lps.transpose() * direction_lps - Eigen::Matrix3d::Identity())
                           .cwiseAbs()
                           .maxCoeff();
  if (!(ortho < 1e-3)) why << "direction cosines are not orthonormal (deviation " << ortho << "); ";
  if (!origin_lps_mm.allFinite()) why << "origin is not finite; ";
  const std::string s = why.str();
  if (!s.empty()) throw GeometryError("invalid voxel grid: " + s.substr(0, s.size() - 2));
}

}  // namespace organsmith
