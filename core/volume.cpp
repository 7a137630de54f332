#include "core/volume.h"

#include <algorithm>
#include <cmath>

namespace organsmith {

std::int64_t LabelMap::count(std::uint8_t value) const {
  return std::count(labels.begin(), labels.end(), value);
}

double LabelMap::volume_ml(std::uint8_t value) const {
  const double voxel_mm3 = grid.spacing_mm.prod();
  return double(count(value)) * voxel_mm3 / 1000.0;
}

std::array<int, 3> axial_axis_order(const ImageGrid& grid) {
  const Eigen::Matrix3d& d = grid.direction_lps;
  std::array<int, 3> order{0, 1, 2};
  int ks = 0;
  for (int a = 1; a < 3; ++a)
    if (std::abs(d(2, a)) > std::abs(d(2, ks))) ks = a;
  int rest[2], n = 0;
  for (int a = 0; a < 3; ++a)
    if (a != ks) rest[n++] = a;
  if (std::abs(d(0, rest[1])) > std::abs(d(0, rest[0]))) std::swap(rest[0], rest[1]);
  order = {rest[0], rest[1], ks};
  return order;
}

ImageGrid permute_grid(const ImageGrid& grid, const std::array<int, 3>& order) {
  ImageGrid g = grid;
  for (int a = 0; a < 3; ++a) {
    g.size_vox[a] = grid.size_vox[order[a]];
    g.spacing_mm[a] = grid.spacing_mm[order[a]];
    g.direction_lps.col(a) = grid.direction_lps.col(order[a]);
  }
  return g;
}

template <typename T>
VoxelBuffer<T> permute_voxels(const VoxelBuffer<T>& in, const ImageGrid& grid, const std::array<int, 3>& order) {
  const ImageGrid g = permute_grid(grid, order);
  VoxelBuffer<T> out;
  out.resize(std::size_t(g.voxel_count()));
  // Stride in the stored buffer of one step along each new axis.
  const std::int64_t stride_old[3] = {1, grid.size_vox[0], grid.size_vox[0] * grid.size_vox[1]};
  const std::int64_t s0 = stride_old[order[0]], s1 = stride_old[order[1]], s2 = stride_old[order[2]];
  std::size_t o = 0;
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i) out[o++] = in[std::size_t(i * s0 + j * s1 + k * s2)];
  return out;
}
template VoxelBuffer<float> permute_voxels(const VoxelBuffer<float>&, const ImageGrid&, const std::array<int, 3>&);
template VoxelBuffer<std::uint8_t> permute_voxels(const VoxelBuffer<std::uint8_t>&, const ImageGrid&,
                                                  const std::array<int, 3>&);

Volume permute_axes(const Volume& v, const std::array<int, 3>& order) {
  Volume out;
  out.grid = permute_grid(v.grid, order);
  out.hu = permute_voxels(v.hu, v.grid, order);
  return out;
}

LabelMap permute_axes(const LabelMap& m, const std::array<int, 3>& order) {
  LabelMap out;
  out.grid = permute_grid(m.grid, order);
  out.labels = permute_voxels(m.labels, m.grid, order);
  return out;
}

}  // namespace organsmith
