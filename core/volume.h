#pragma once
// Scalar CT volume and label map on a regular grid, LPS millimetres.

#include "core/buffer.h"
#include "core/grid.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace organsmith {

/// A CT volume in Hounsfield units (rescale slope/intercept already applied).
/// `hu` holds grid.voxel_count() values, i fastest, then j, then k. (Its resize() does not
/// zero new voxels; see core/buffer.h.)
struct Volume {
  ImageGrid grid;
  VoxelBuffer<float> hu;

  float at(std::int64_t i, std::int64_t j, std::int64_t k) const { return hu[grid.offset(i, j, k)]; }
  /// Pointer to the first voxel of slice k (size_vox[0] * size_vox[1] values).
  const float* slice(std::int64_t k) const { return hu.data() + k * grid.slice_voxel_count(); }
};

/// Per-voxel uint8 labels on the grid of a Volume; 0 is background. Which organ a value is comes
/// from the organ registry (data/organs.toml), never from here. resize() does not zero new
/// voxels; use assign(n, 0).
struct LabelMap {
  ImageGrid grid;
  VoxelBuffer<std::uint8_t> labels;

  std::uint8_t at(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return labels[grid.offset(i, j, k)];
  }
  /// Number of voxels carrying `value`.
  std::int64_t count(std::uint8_t value) const;
  /// Volume of the voxels carrying `value`, in millilitres.
  double volume_ml(std::uint8_t value) const;
};

/// Storage order that puts a grid's slices across the body's long axis: order[a] is the stored
/// axis that becomes axis a, k being the stored axis closest to S and i the remaining one closest
/// to L. {0, 1, 2} for a volume already stored as axial (or oblique-axial) slices.
std::array<int, 3> axial_axis_order(const ImageGrid& grid);

/// The same voxels stored in another axis order (a lossless copy, see `axial_axis_order`): the
/// grid's size, spacing and direction columns are permuted, the origin is kept, so every voxel
/// keeps its LPS position.
template <typename T>
VoxelBuffer<T> permute_voxels(const VoxelBuffer<T>& in, const ImageGrid& grid, const std::array<int, 3>& order);
ImageGrid permute_grid(const ImageGrid& grid, const std::array<int, 3>& order);
Volume permute_axes(const Volume& v, const std::array<int, 3>& order);
LabelMap permute_axes(const LabelMap& m, const std::array<int, 3>& order);

}  // namespace organsmith
