#pragma once
// Voxel grid geometry in DICOM patient coordinates (LPS, millimetres).

#include <Eigen/Core>

#include <array>
#include <cstdint>

namespace organsmith {

/// Geometry of a regular voxel grid.
///
/// Index (i, j, k) runs along columns, rows and slices (i fastest in memory). The physical
/// position of a voxel centre is
///     p_lps_mm = origin_lps_mm + direction_lps * diag(spacing_mm) * (i, j, k)^T
/// where the columns of `direction_lps` are the unit vectors of the i, j and k axes in LPS
/// (for DICOM: row direction, column direction, slice normal). This is the ITK convention, so
/// ITK images convert without reinterpretation; NIfTI's RAS affine is obtained by negating the
/// first two rows (see `index_to_ras_affine`).
struct ImageGrid {
  std::array<std::int64_t, 3> size_vox{0, 0, 0};  ///< voxels along i, j, k
  Eigen::Vector3d spacing_mm{1.0, 1.0, 1.0};        ///< voxel size along i, j, k (mm, > 0)
  Eigen::Vector3d origin_lps_mm{0.0, 0.0, 0.0};     ///< centre of voxel (0, 0, 0), LPS mm
  Eigen::Matrix3d direction_lps = Eigen::Matrix3d::Identity();  ///< columns: axis unit vectors

  std::int64_t voxel_count() const { return size_vox[0] * size_vox[1] * size_vox[2]; }
  std::int64_t slice_voxel_count() const { return size_vox[0] * size_vox[1]; }
  /// Linear offset of (i, j, k) in an i-fastest buffer.
  std::int64_t offset(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return i + size_vox[0] * (j + size_vox[1] * k);
  }
  bool contains(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return i >= 0 && j >= 0 && k >= 0 && i < size_vox[0] && j < size_vox[1] && k < size_vox[2];
  }

  /// Continuous index (i, j, k) → LPS position in mm.
  Eigen::Vector3d index_to_lps_mm(const Eigen::Vector3d& ijk) const;
  /// LPS position in mm → continuous index (exact inverse of `index_to_lps_mm`).
  Eigen::Vector3d lps_mm_to_index(const Eigen::Vector3d& p_lps_mm) const;
  /// 4×4 homogeneous matrix mapping (i, j, k, 1) to (L, P, S, 1) in mm.
  Eigen::Matrix4d index_to_lps_affine() const;
  /// 4×4 homogeneous matrix mapping (i, j, k, 1) to (R, A, S, 1) in mm (NIfTI's convention).
  Eigen::Matrix4d index_to_ras_affine() const;
  /// Physical extent of the voxel centres along each LPS axis: (min, max) corners.
  std::array<Eigen::Vector3d, 2> bounds_lps_mm() const;

  /// True when both grids have the same size and their voxel centres agree within tol_mm.
  bool same_geometry(const ImageGrid& other, double tol_mm = 1e-3) const;
  /// Throws GeometryError when the direction matrix is not orthonormal or spacing not positive.
  void validate() const;
};

/// Converts between LPS and RAS (the same map in both directions: negate x and y).
inline Eigen::Vector3d lps_to_ras(const Eigen::Vector3d& p) { return {-p.x(), -p.y(), p.z()}; }
inline Eigen::Vector3d ras_to_lps(const Eigen::Vector3d& p) { return {-p.x(), -p.y(), p.z()}; }

}  // namespace organsmith
