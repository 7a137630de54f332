#pragma once
// Grid tools of the 3-D surface (segmentation/surface3d.cpp) on its working box: exact
// anisotropic distance transform, separable Gaussian, running-sum box filter, central
// differences and topology clean-up. Private to segmentation (TBB only inside for_slices).

#include <cstddef>
#include <cstdint>
#include <vector>

#include <tbb/parallel_for.h>

namespace organsmith::seg::detail {

/// The working box: a sub-grid of the volume, x fastest.
struct Box {
  std::int64_t i0 = 0, j0 = 0, k0 = 0;
  int nx = 0, ny = 0, nz = 0;
  double hx = 1, hy = 1, hz = 1;
  std::size_t size() const { return std::size_t(nx) * ny * nz; }
  std::size_t at(int x, int y, int z) const { return (std::size_t(z) * ny + y) * nx + x; }
};

/// First element of line l along axis ax (0 = x, 1 = y, 2 = z) of an nx × ny × … grid, x fastest;
/// len is the line's length.
inline std::size_t line_start(int ax, std::size_t l, int nx, int ny, int len) {
  if (ax == 0) return l * std::size_t(len);
  if (ax == 1) return (l / std::size_t(nx)) * std::size_t(nx) * std::size_t(ny) + (l % std::size_t(nx));
  return l;
}

/// f(z) for every slice of the box, on TBB workers when `parallel`.
template <class F>
void for_slices(const Box& b, bool parallel, F&& f) {
  if (parallel)
    tbb::parallel_for(0, b.nz, [&](int z) { f(z); });
  else
    for (int z = 0; z < b.nz; ++z) f(z);
}

/// A gradient, per mm.
struct Grad {
  double x, y, z;
};

/// Separable Gaussian of σ mm along each axis whose σ is at least half a voxel (zero-flux borders).
void gaussian(std::vector<float>& a, const Box& b, double sigma_mm);

/// Sums of `cur` over the (2rx+1)(2ry+1)(2rz+1) window around every voxel, truncated at the box's
/// faces (running sums along each axis), in place; `nxt` is scratch of the same size (kept by the
/// caller: fresh arrays of a few MB each call cost more in page faults than the sums).
void box_sum(std::vector<float>& cur, std::vector<float>& nxt, const Box& b, int rx, int ry, int rz);

/// Central differences in mm (one-sided at the box's faces).
Grad central(const std::vector<float>& a, const Box& b, int x, int y, int z);

/// Connected (6-neighbour) part of `in` that touches `seed`, with enclosed background filled.
std::vector<std::uint8_t> simple_topology(const std::vector<std::uint8_t>& in, const std::vector<std::uint8_t>& seed,
                                          const Box& b);

/// Squared Euclidean distance, mm², from every voxel of an nx × ny × nz grid (x fastest, spacing
/// hx, hy, hz) to the nearest voxel with `feature` non-zero (exact, separable; Felzenszwalb &
/// Huttenlocher's lower envelope). Infinity everywhere when there is no feature voxel.
std::vector<float> distance_sq_mm2(const std::vector<std::uint8_t>& feature, int nx, int ny, int nz, double hx,
                                   double hy, double hz);

}  // namespace organsmith::seg::detail
