// Planar cuts through a CT volume and its label map.

#include "viewer/detail/slice.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>

namespace organsmith::viewer_detail {

std::string slice_axis_name(SliceAxis a) {
  switch (a) {
    case SliceAxis::axial: return "axial";
    case SliceAxis::coronal: return "coronal";
    case SliceAxis::sagittal: return "sagittal";
  }
  return "?";
}

SliceFrame slice_frame(SliceAxis a) {
  switch (a) {
    case SliceAxis::axial: return {{1, 0, 0}, {0, -1, 0}, {0, 0, 1}};
    case SliceAxis::coronal: return {{1, 0, 0}, {0, 0, 1}, {0, 1, 0}};
    case SliceAxis::sagittal: return {{0, 1, 0}, {0, 0, 1}, {1, 0, 0}};
  }
  return {};
}

char direction_letter(const Eigen::Vector3d& v) {
  int axis = 0;
  v.cwiseAbs().maxCoeff(&axis);
  return v[axis] > 0 ? "LPS"[axis] : "RAI"[axis];
}

bool label_centroid(const LabelMap& labels, std::uint8_t label, Eigen::Vector3d& centroid) {
  const auto& g = labels.grid;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  std::int64_t n = 0;
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j) {
      const std::uint8_t* row = labels.labels.data() + g.offset(0, j, k);
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
        if (row[i] == label) {
          sum += Eigen::Vector3d(double(i), double(j), double(k));
          ++n;
        }
    }
  if (n == 0) return false;
  centroid = g.index_to_lps_mm(sum / double(n));
  return true;
}

SliceSample sample_slice(const Volume& ct, const LabelMap* labels, SliceAxis axis, const Eigen::Vector3d& centre) {
  const ImageGrid& g = ct.grid;
  SliceSample s;
  s.axis = axis;
  s.frame = slice_frame(axis);
  s.centre_lps_mm = centre;
  // Square pixels as fine as the finest in-plane voxel spacing.
  s.pixel_mm = g.spacing_mm.minCoeff();
  double smin = 1e300, smax = -1e300, tmin = 1e300, tmax = -1e300;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d ijk((c & 1) ? g.size_vox[0] - 0.5 : -0.5, (c & 2) ? g.size_vox[1] - 0.5 : -0.5,
                              (c & 4) ? g.size_vox[2] - 0.5 : -0.5);
    const Eigen::Vector3d q = g.index_to_lps_mm(ijk) - centre;
    smin = std::min(smin, q.dot(s.frame.right));
    smax = std::max(smax, q.dot(s.frame.right));
    tmin = std::min(tmin, q.dot(s.frame.up));
    tmax = std::max(tmax, q.dot(s.frame.up));
  }
  s.width = std::max(1, int(std::floor((smax - smin) / s.pixel_mm)));
  s.height = std::max(1, int(std::floor((tmax - tmin) / s.pixel_mm)));
  s.s0 = smin + 0.5 * s.pixel_mm;
  s.t0 = tmin + 0.5 * s.pixel_mm;
  s.hu.assign(std::size_t(s.width) * s.height, std::numeric_limits<float>::quiet_NaN());
  const bool with_labels = labels && labels->grid.same_geometry(g);
  if (with_labels) s.labels.assign(std::size_t(s.width) * s.height, 0);

  // Continuous index of pixel (x, y) = base + x·di + y·dj.
  const Eigen::Vector3d base = g.lps_mm_to_index(centre + s.frame.right * s.s0 + s.frame.up * s.t0);
  const Eigen::Vector3d di = g.lps_mm_to_index(centre + s.frame.right * (s.s0 + s.pixel_mm) + s.frame.up * s.t0) - base;
  const Eigen::Vector3d dj = g.lps_mm_to_index(centre + s.frame.right * s.s0 + s.frame.up * (s.t0 + s.pixel_mm)) - base;
  const auto nx = g.size_vox[0], ny = g.size_vox[1], nz = g.size_vox[2];
  tbb::parallel_for(0, s.height, [&](int y) {
    for (int x = 0; x < s.width; ++x) {
      const Eigen::Vector3d f = base + di * x + dj * y;
      const double fi = std::clamp(f.x(), 0.0, double(nx - 1)), fj = std::clamp(f.y(), 0.0, double(ny - 1)),
                   fk = std::clamp(f.z(), 0.0, double(nz - 1));
      if (std::abs(fi - f.x()) > 0.5 || std::abs(fj - f.y()) > 0.5 || std::abs(fk - f.z()) > 0.5) continue;
      const std::int64_t i0 = std::min<std::int64_t>(std::int64_t(fi), nx - 1), j0 = std::min<std::int64_t>(std::int64_t(fj), ny - 1),
                         k0 = std::min<std::int64_t>(std::int64_t(fk), nz - 1);
      const std::int64_t i1 = std::min(i0 + 1, nx - 1), j1 = std::min(j0 + 1, ny - 1), k1 = std::min(k0 + 1, nz - 1);
      const double a = fi - double(i0), b = fj - double(j0), c = fk - double(k0);
      auto v = [&](std::int64_t i, std::int64_t j, std::int64_t k) { return double(ct.hu[g.offset(i, j, k)]); };
      const double c00 = v(i0, j0, k0) * (1 - a) + v(i1, j0, k0) * a, c10 = v(i0, j1, k0) * (1 - a) + v(i1, j1, k0) * a;
      const double c01 = v(i0, j0, k1) * (1 - a) + v(i1, j0, k1) * a, c11 = v(i0, j1, k1) * (1 - a) + v(i1, j1, k1) * a;
      const double val = (c00 * (1 - b) + c10 * b) * (1 - c) + (c01 * (1 - b) + c11 * b) * c;
      const std::size_t px = std::size_t(y) * s.width + x;
      s.hu[px] = float(val);
      if (with_labels)
        s.labels[px] = labels->at(std::clamp<std::int64_t>(std::llround(f.x()), 0, nx - 1),
                                  std::clamp<std::int64_t>(std::llround(f.y()), 0, ny - 1),
                                  std::clamp<std::int64_t>(std::llround(f.z()), 0, nz - 1));
    }
  });
  return s;
}

}  // namespace organsmith::viewer_detail
