// The airway wall split into cartilage rings and membrane (see tube_regions.h).

#include "meshing/tube_regions.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <vector>

namespace organsmith {

TubeSplit split_tube_wall(TetMesh& wall, const TubeRings& rings) {
  TubeSplit out;
  const std::size_t n = wall.tets.size();
  if (n == 0 || !(rings.pitch_mm > 0)) return out;
  std::vector<Eigen::Vector3d> c(n);
  std::vector<double> vol(n);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double total = 0;
  for (std::size_t t = 0; t < n; ++t) {
    c[t] = Eigen::Vector3d::Zero();
    for (auto v : wall.tets[t]) c[t] += wall.vertices_lps_mm[std::size_t(v)] / 4.0;
    vol[t] = std::abs(wall.tet_volume_mm3(t));
    mean += vol[t] * c[t];
    total += vol[t];
  }
  mean /= total;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (std::size_t t = 0; t < n; ++t) cov += vol[t] * (c[t] - mean) * (c[t] - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Vector3d axis = eig.eigenvectors().col(2).normalized();
  if (axis.z() < 0) axis = -axis;  // superior (LPS +z)
  out.axis_lps = axis;

  // Centreline: the volume centroid of the wall in slabs along the axis (a full ring of wall in
  // each slab, so its centroid is the tube's centre there), smoothed over three slabs.
  constexpr double kSlab = 2.0;
  double smin = 1e300, smax = -1e300;
  std::vector<double> s(n);
  for (std::size_t t = 0; t < n; ++t) {
    s[t] = (c[t] - mean).dot(axis);
    smin = std::min(smin, s[t]);
    smax = std::max(smax, s[t]);
  }
  out.length_mm = smax - smin;
  const int bins = std::max(1, int(std::ceil((smax - smin) / kSlab)));
  std::vector<Eigen::Vector3d> sum(std::size_t(bins), Eigen::Vector3d::Zero());
  std::vector<double> w(std::size_t(bins), 0.0);
  auto bin_of = [&](double x) { return std::clamp(int((x - smin) / kSlab), 0, bins - 1); };
  for (std::size_t t = 0; t < n; ++t) {
    sum[std::size_t(bin_of(s[t]))] += vol[t] * c[t];
    w[std::size_t(bin_of(s[t]))] += vol[t];
  }
  std::vector<Eigen::Vector3d> centre(std::size_t(bins), mean);
  for (int b = 0; b < bins; ++b)
    if (w[std::size_t(b)] > 0) centre[std::size_t(b)] = sum[std::size_t(b)] / w[std::size_t(b)];
  for (int b = 0; b < bins; ++b)  // an empty slab takes its nearest filled neighbour's centre
    if (w[std::size_t(b)] <= 0)
      for (int d = 1; d < bins; ++d) {
        if (b - d >= 0 && w[std::size_t(b - d)] > 0) { centre[std::size_t(b)] = centre[std::size_t(b - d)]; break; }
        if (b + d < bins && w[std::size_t(b + d)] > 0) { centre[std::size_t(b)] = centre[std::size_t(b + d)]; break; }
      }
  std::vector<Eigen::Vector3d> smooth(centre);
  for (int b = 0; b < bins; ++b) {
    Eigen::Vector3d acc = Eigen::Vector3d::Zero();
    int k = 0;
    for (int d = -1; d <= 1; ++d)
      if (b + d >= 0 && b + d < bins) acc += centre[std::size_t(b + d)], ++k;
    smooth[std::size_t(b)] = acc / k;
  }
  auto centre_at = [&](double x) {  // linear between slab centres
    const double f = std::clamp((x - smin) / kSlab - 0.5, 0.0, double(bins - 1));
    const int b = std::min(int(f), bins - 1), b1 = std::min(b + 1, bins - 1);
    return Eigen::Vector3d((1 - (f - b)) * smooth[std::size_t(b)] + (f - b) * smooth[std::size_t(b1)]);
  };

  // Posterior (LPS +y) across the axis; the membrane's half-arc around it.
  Eigen::Vector3d posterior = Eigen::Vector3d::UnitY() - axis.y() * axis;
  if (posterior.norm() < 1e-6) posterior = Eigen::Vector3d::UnitX() - axis.x() * axis;  // an axis along y
  posterior.normalize();
  const double half_membrane_rad = (360.0 - std::clamp(rings.cartilage_arc_deg, 0.0, 360.0)) * M_PI / 360.0;
  wall.region_ids.assign(n, kRegionTubeMembrane);
  for (std::size_t t = 0; t < n; ++t) {
    Eigen::Vector3d r = c[t] - centre_at(s[t]);
    r -= r.dot(axis) * axis;
    const double angle = r.norm() > 1e-9 ? std::acos(std::clamp(r.normalized().dot(posterior), -1.0, 1.0)) : 0.0;
    const double phase = std::fmod(smax - s[t], rings.pitch_mm);  // from the cranial end
    const bool cartilage = angle > half_membrane_rad && phase < rings.height_mm;
    wall.region_ids[t] = cartilage ? kRegionTubeCartilage : kRegionTubeMembrane;
    (cartilage ? out.cartilage_tets : out.membrane_tets) += 1;
    (cartilage ? out.cartilage_volume_mm3 : out.membrane_volume_mm3) += vol[t];
  }
  return out;
}

}  // namespace organsmith
