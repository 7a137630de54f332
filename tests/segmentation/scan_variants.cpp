// Over 400 lines: the sweeps' scan variants, their scoring against the reference and the
// enclosed-solid Dice of a mesh share the grid helpers of this file's anonymous namespace.

#include "scan_variants.h"

#include <cstdlib>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace organsmith::testing {

namespace {

std::int64_t lowest_k(const LabelMap& m, bool highest) {
  const auto& n = m.grid.size_vox;
  std::int64_t best = -1;
  for (std::int64_t k = 0; k < n[2]; ++k) {
    const std::uint8_t* s = m.labels.data() + k * m.grid.slice_voxel_count();
    if (std::any_of(s, s + m.grid.slice_voxel_count(), [](std::uint8_t v) { return v != 0; })) {
      if (!highest) return k;
      best = k;
    }
  }
  return best;
}

/// The reference voxel nearest to the centroid of the reference on its largest slice in [k0, k1].
Eigen::Vector3d central_voxel(const LabelMap& m, std::int64_t k0, std::int64_t k1) {
  const auto& n = m.grid.size_vox;
  std::int64_t bk = k0, barea = -1;
  for (std::int64_t k = k0; k <= k1; ++k) {
    const std::uint8_t* s = m.labels.data() + k * m.grid.slice_voxel_count();
    const auto a = std::count_if(s, s + m.grid.slice_voxel_count(), [](std::uint8_t v) { return v != 0; });
    if (a > barea) barea = a, bk = k;
  }
  Eigen::Vector2d c(0, 0);
  std::int64_t cnt = 0;
  for (std::int64_t j = 0; j < n[1]; ++j)
    for (std::int64_t i = 0; i < n[0]; ++i)
      if (m.at(i, j, bk)) c += Eigen::Vector2d(double(i), double(j)), ++cnt;
  c /= double(std::max<std::int64_t>(cnt, 1));
  Eigen::Vector3d best(c.x(), c.y(), double(bk));
  double bd = 1e300;
  for (std::int64_t j = 0; j < n[1]; ++j)
    for (std::int64_t i = 0; i < n[0]; ++i)
      if (m.at(i, j, bk)) {
        const double d = (Eigen::Vector2d(double(i), double(j)) - c).norm();
        if (d < bd) bd = d, best = Eigen::Vector3d(double(i), double(j), double(bk));
      }
  return m.grid.index_to_lps_mm(best);
}

}  // namespace

Scan resample_slices(const Scan& s, double slice_mm) {
  const ImageGrid& g = s.ct.grid;
  const double t_old = g.spacing_mm.z();
  const std::int64_t K = g.size_vox[2];
  const double extent = double(K - 1) * t_old;
  const std::int64_t Kn = std::int64_t(std::floor(extent / slice_mm + 1e-9)) + 1;
  Scan out;
  out.seed_lps_mm = s.seed_lps_mm;
  out.ct.grid = g;
  out.ct.grid.size_vox[2] = Kn;
  out.ct.grid.spacing_mm.z() = slice_mm;
  out.ref.grid = out.ct.grid;
  const std::int64_t plane = g.slice_voxel_count();
  out.ct.hu.resize(std::size_t(plane * Kn));
  out.ref.labels.assign(std::size_t(plane * Kn), 0);
  // Box of width max(new, old) around the new slice against each old slice's box: a thick slice
  // averages what it covers, a thin one interpolates linearly (the overlap of two equal boxes).
  const double w = std::max(slice_mm, t_old);
  std::vector<double> acc(static_cast<std::size_t>(plane)), lab(static_cast<std::size_t>(plane));
  for (std::int64_t kn = 0; kn < Kn; ++kn) {
    const double z = double(kn) * slice_mm;
    std::fill(acc.begin(), acc.end(), 0.0);
    std::fill(lab.begin(), lab.end(), 0.0);
    double wsum = 0;
    for (std::int64_t k = 0; k < K; ++k) {
      const double zk = double(k) * t_old;
      const double ov = std::min(z + w / 2, zk + t_old / 2) - std::max(z - w / 2, zk - t_old / 2);
      if (ov <= 0) continue;
      wsum += ov;
      const float* h = s.ct.slice(k);
      const std::uint8_t* l = s.ref.labels.data() + k * plane;
      for (std::int64_t q = 0; q < plane; ++q) acc[q] += ov * h[q], lab[q] += ov * (l[q] != 0);
    }
    for (std::int64_t q = 0; q < plane; ++q) {
      out.ct.hu[std::size_t(kn * plane + q)] = float(acc[q] / wsum);
      out.ref.labels[std::size_t(kn * plane + q)] = lab[q] / wsum >= 0.5 ? 1 : 0;
    }
  }
  return out;
}

Scan crop_through_organ(const Scan& s, double fraction, bool keep_low_k) {
  const std::int64_t a = lowest_k(s.ref, false), b = lowest_k(s.ref, true);
  const std::int64_t cut = a + std::int64_t(std::lround(fraction * double(b - a)));
  const std::int64_t k0 = keep_low_k ? 0 : cut, k1 = keep_low_k ? cut : s.ct.grid.size_vox[2] - 1;
  Scan out;
  out.ct.grid = s.ct.grid;
  out.ct.grid.size_vox[2] = k1 - k0 + 1;
  out.ct.grid.origin_lps_mm = s.ct.grid.index_to_lps_mm(Eigen::Vector3d(0, 0, double(k0)));
  out.ref.grid = out.ct.grid;
  const std::int64_t plane = s.ct.grid.slice_voxel_count();
  out.ct.hu.assign(s.ct.hu.begin() + k0 * plane, s.ct.hu.begin() + (k1 + 1) * plane);
  out.ref.labels.assign(s.ref.labels.begin() + k0 * plane, s.ref.labels.begin() + (k1 + 1) * plane);
  const double sk = s.ct.grid.lps_mm_to_index(s.seed_lps_mm).z();
  const bool seed_kept = sk >= double(k0) + 0.5 && sk <= double(k1) - 0.5;
  out.seed_lps_mm = seed_kept ? s.seed_lps_mm
                              : central_voxel(out.ref, std::max<std::int64_t>(0, lowest_k(out.ref, false)),
                                              std::max<std::int64_t>(0, lowest_k(out.ref, true)));
  return out;
}

Scan shifted_origin(const Scan& s, const Eigen::Vector3d& shift_mm) {
  Scan out = s;
  out.ct.grid.origin_lps_mm += shift_mm;
  out.ref.grid.origin_lps_mm += shift_mm;
  out.seed_lps_mm += shift_mm;
  return out;
}

Scan scaled_spacing(const Scan& s, double factor) {
  Scan out = s;
  const Eigen::Vector3d index = s.ct.grid.lps_mm_to_index(s.seed_lps_mm);
  out.ct.grid.spacing_mm *= factor;
  out.ref.grid.spacing_mm *= factor;
  out.seed_lps_mm = out.ct.grid.index_to_lps_mm(index);
  return out;
}

Scan stored_ras(const Scan& s) {
  const ImageGrid& g = s.ct.grid;
  const auto& n = g.size_vox;
  Scan out;
  out.seed_lps_mm = s.seed_lps_mm;
  out.ct.grid = g;
  out.ct.grid.direction_lps.col(0) *= -1;
  out.ct.grid.direction_lps.col(1) *= -1;
  out.ct.grid.origin_lps_mm = g.index_to_lps_mm(Eigen::Vector3d(double(n[0] - 1), double(n[1] - 1), 0));
  out.ref.grid = out.ct.grid;
  out.ct.hu.resize(s.ct.hu.size());
  out.ref.labels.resize(s.ref.labels.size());
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i) {
        const auto from = g.offset(n[0] - 1 - i, n[1] - 1 - j, k), to = g.offset(i, j, k);
        out.ct.hu[std::size_t(to)] = s.ct.hu[std::size_t(from)];
        out.ref.labels[std::size_t(to)] = s.ref.labels[std::size_t(from)];
      }
  return out;
}

Scan stored_sagittal(const Scan& s) {
  const std::array<int, 3> order{1, 2, 0};  // new i = P, new j = S, new k = L
  Scan out;
  out.seed_lps_mm = s.seed_lps_mm;
  out.ct = permute_axes(s.ct, order);
  out.ref = permute_axes(s.ref, order);
  return out;
}

Scan tilted(const Scan& s, double degrees) {
  const ImageGrid& g = s.ct.grid;
  const Eigen::Vector3d c = g.index_to_lps_mm(
      Eigen::Vector3d(double(g.size_vox[0] - 1), double(g.size_vox[1] - 1), double(g.size_vox[2] - 1)) / 2.0);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(degrees * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
  Scan out = s;
  out.ct.grid.direction_lps = R * g.direction_lps;
  out.ct.grid.origin_lps_mm = c + R * (g.origin_lps_mm - c);
  out.ref.grid = out.ct.grid;
  out.seed_lps_mm = c + R * (s.seed_lps_mm - c);
  return out;
}

Scan contrast_enhanced(const Scan& s, const LabelMap& organ, double boost_hu, double blur_mm) {
  Scan out = s;
  const ImageGrid& g = s.ct.grid;
  std::vector<double> m(organ.labels.begin(), organ.labels.end());
  for (double& v : m) v = v != 0 ? 1.0 : 0.0;
  // Separable Gaussian, σ in voxels per axis.
  for (int a = 0; a < 3; ++a) {
    const double sigma = blur_mm / g.spacing_mm[a];
    const int r = int(std::ceil(3 * sigma));
    if (r < 1) continue;
    std::vector<double> w(std::size_t(2 * r + 1));
    double ws = 0;
    for (int t = -r; t <= r; ++t) ws += w[std::size_t(t + r)] = std::exp(-0.5 * t * t / (sigma * sigma));
    std::vector<double> res(m.size(), 0.0);
    const auto& n = g.size_vox;
    for (std::int64_t k = 0; k < n[2]; ++k)
      for (std::int64_t j = 0; j < n[1]; ++j)
        for (std::int64_t i = 0; i < n[0]; ++i) {
          double acc = 0;
          for (int t = -r; t <= r; ++t) {
            std::int64_t q[3] = {i, j, k};
            q[a] = std::clamp<std::int64_t>(q[a] + t, 0, n[a] - 1);
            acc += w[std::size_t(t + r)] * m[std::size_t(g.offset(q[0], q[1], q[2]))];
          }
          res[std::size_t(g.offset(i, j, k))] = acc / ws;
        }
    m.swap(res);
  }
  for (std::size_t q = 0; q < m.size(); ++q) out.ct.hu[q] += float(boost_hu * m[q]);
  return out;
}

Scan with_noise(const Scan& s, double sigma_hu, unsigned seed) {
  Scan out = s;
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0.0f, float(sigma_hu));
  for (float& v : out.ct.hu) v += n(rng);
  return out;
}

Eigen::Vector3d seed_at_centre(const LabelMap& ref) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  std::int64_t n = 0;
  const auto& sz = ref.grid.size_vox;
  for (std::int64_t k = 0; k < sz[2]; ++k)
    for (std::int64_t j = 0; j < sz[1]; ++j)
      for (std::int64_t i = 0; i < sz[0]; ++i)
        if (ref.at(i, j, k)) c += Eigen::Vector3d(double(i), double(j), double(k)), ++n;
  c /= double(n);
  Eigen::Vector3d best = c;
  double bd = 1e300;
  for (std::int64_t k = 0; k < sz[2]; ++k)
    for (std::int64_t j = 0; j < sz[1]; ++j)
      for (std::int64_t i = 0; i < sz[0]; ++i)
        if (ref.at(i, j, k)) {
          const Eigen::Vector3d q{double(i), double(j), double(k)};
          if ((q - c).norm() < bd) bd = (q - c).norm(), best = q;
        }
  return ref.grid.index_to_lps_mm(best);
}

Eigen::Vector3d seed_near_end(const Scan& s, int which, double depth_mm) {
  const ImageGrid& g = s.ref.grid;
  const auto& n = g.size_vox;
  std::vector<Eigen::Vector3d> idx;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i)
        if (s.ref.at(i, j, k)) {
          idx.emplace_back(double(i), double(j), double(k));
          mean += g.index_to_lps_mm(idx.back());
        }
  mean /= double(idx.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& q : idx) {
    const Eigen::Vector3d d = g.index_to_lps_mm(q) - mean;
    cov += d * d.transpose();
  }
  const Eigen::Vector3d axis = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvectors().col(2);
  std::vector<double> proj;
  for (const auto& q : idx) proj.push_back(double(which) * (g.index_to_lps_mm(q) - mean).dot(axis));
  std::vector<double> sorted = proj;
  std::sort(sorted.begin(), sorted.end());
  const double cut = sorted[std::size_t(0.85 * double(sorted.size() - 1))];
  // Among the voxels in the last 15 % along the axis, the one deepest in plane (capped at
  // depth_mm), then the one furthest along.
  const int ri = int(std::ceil(depth_mm / g.spacing_mm.x())), rj = int(std::ceil(depth_mm / g.spacing_mm.y()));
  double best_depth = -1, best_proj = -1e300;
  Eigen::Vector3d best = idx.front();
  for (std::size_t q = 0; q < idx.size(); ++q) {
    if (proj[q] < cut) continue;
    const auto i0 = std::int64_t(idx[q].x()), j0 = std::int64_t(idx[q].y()), k0 = std::int64_t(idx[q].z());
    double depth = depth_mm;
    for (int dj = -rj; dj <= rj; ++dj)
      for (int di = -ri; di <= ri; ++di) {
        const double d = std::hypot(di * g.spacing_mm.x(), dj * g.spacing_mm.y());
        if (d >= depth) continue;
        const std::int64_t i = i0 + di, j = j0 + dj;
        if (!g.contains(i, j, k0) || !s.ref.at(i, j, k0)) depth = d;
      }
    if (depth > best_depth + 1e-9 || (std::abs(depth - best_depth) <= 1e-9 && proj[q] > best_proj))
      best_depth = depth, best_proj = proj[q], best = idx[q];
  }
  return g.index_to_lps_mm(best);
}

Score score_against(const LabelMap& ref, const LabelMap& test, std::uint8_t test_label) {
  std::int64_t a = 0, b = 0, ab = 0;
  for (std::uint8_t v : test.labels) b += v == test_label;
  const auto& s = ref.grid.size_vox;
  for (std::int64_t k = 0; k < s[2]; ++k)
    for (std::int64_t j = 0; j < s[1]; ++j)
      for (std::int64_t i = 0; i < s[0]; ++i) {
        if (!ref.at(i, j, k)) continue;
        ++a;
        const Eigen::Vector3d t =
            test.grid.lps_mm_to_index(ref.grid.index_to_lps_mm(Eigen::Vector3d(double(i), double(j), double(k))));
        const std::int64_t ti = std::llround(t.x()), tj = std::llround(t.y()), tk = std::llround(t.z());
        if (test.grid.contains(ti, tj, tk) && test.at(ti, tj, tk) == test_label) ++ab;
      }
  Score r;
  r.dice = a + b ? 2.0 * double(ab) / double(a + b) : 0.0;
  r.volume_error = a ? double(b - a) / double(a) : 0.0;
  return r;
}

double enclosed_dice(const SurfaceMesh& surface, const LabelMap& lm, std::uint8_t value) {
  const ImageGrid& g = lm.grid;
  auto in_label = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    if (!g.contains(i, j, k)) return false;
    const std::uint8_t l = lm.labels[std::size_t(g.offset(i, j, k))];
    return value == 0 ? l != 0 : l == value;
  };
  std::vector<Eigen::Vector3d> v;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (const auto& p : surface.vertices_lps_mm) {
    v.push_back(g.lps_mm_to_index(p));
    lo = lo.cwiseMin(v.back()), hi = hi.cwiseMax(v.back());
  }
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
        if (in_label(i, j, k)) {
          const Eigen::Vector3d q{double(i), double(j), double(k)};
          lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
        }
  constexpr int S = 2;  // samples per voxel and axis, at ±1/4 voxel from its centre
  std::array<std::int64_t, 3> a0{}, n{};
  for (int a = 0; a < 3; ++a) a0[a] = std::int64_t(std::floor(lo[a])) - 1, n[a] = (std::int64_t(std::ceil(hi[a])) + 1 - a0[a] + 1) * S;
  auto coord = [&](int a, std::int64_t t) { return double(a0[a]) - 0.5 + (double(t) + 0.5) / S; };
  // Triangles by the sample rows (j, k) their box covers; a row's crossings along i by parity.
  std::vector<std::vector<std::int32_t>> rows(std::size_t(n[1] * n[2]));
  for (std::size_t t = 0; t < surface.triangles.size(); ++t) {
    const auto& T = surface.triangles[t];
    double jl = 1e300, jh = -1e300, kl = 1e300, kh = -1e300;
    for (const int c : T) jl = std::min(jl, v[c][1]), jh = std::max(jh, v[c][1]), kl = std::min(kl, v[c][2]), kh = std::max(kh, v[c][2]);
    const auto t0 = [&](int a, double x) { return std::max<std::int64_t>(0, std::int64_t(std::ceil((x - a0[a] + 0.5) * S - 0.5))); };
    const auto t1 = [&](int a, double x) { return std::min<std::int64_t>(n[a] - 1, std::int64_t(std::floor((x - a0[a] + 0.5) * S - 0.5))); };
    for (std::int64_t tk = t0(2, kl); tk <= t1(2, kh); ++tk)
      for (std::int64_t tj = t0(1, jl); tj <= t1(1, jh); ++tj) rows[std::size_t(tj + n[1] * tk)].push_back(std::int32_t(t));
  }
  double both = 0, mesh = 0, label = 0;
  std::vector<double> xs;
  for (std::int64_t tk = 0; tk < n[2]; ++tk)
    for (std::int64_t tj = 0; tj < n[1]; ++tj) {
      const double y = coord(1, tj), z = coord(2, tk);
      xs.clear();
      for (const std::int32_t t : rows[std::size_t(tj + n[1] * tk)]) {
        const auto& T = surface.triangles[std::size_t(t)];
        const Eigen::Vector3d &A = v[T[0]], &B = v[T[1]], &C = v[T[2]];
        const double d = (B[1] - A[1]) * (C[2] - A[2]) - (C[1] - A[1]) * (B[2] - A[2]);
        if (d == 0) continue;
        const double u = ((y - A[1]) * (C[2] - A[2]) - (C[1] - A[1]) * (z - A[2])) / d;
        const double w = ((B[1] - A[1]) * (z - A[2]) - (y - A[1]) * (B[2] - A[2])) / d;
        if (u < 0 || w < 0 || u + w > 1) continue;
        xs.push_back(A[0] + u * (B[0] - A[0]) + w * (C[0] - A[0]));
      }
      std::sort(xs.begin(), xs.end());
      std::size_t c = 0;
      for (std::int64_t ti = 0; ti < n[0]; ++ti) {
        const double x = coord(0, ti);
        while (c < xs.size() && xs[c] < x) ++c;
        const bool m = c % 2 == 1;
        const bool l = in_label(std::llround(x), std::llround(y), std::llround(z));
        both += m && l, mesh += m, label += l;
      }
    }
  return mesh + label > 0 ? 2 * both / (mesh + label) : 0.0;
}

LabelMap air_under_reference(const Scan& s, float air_hu) {
  LabelMap m;
  m.grid = s.ct.grid;
  m.labels.assign(s.ct.hu.size(), 0);
  const std::int64_t W = s.ct.grid.size_vox[0], H = s.ct.grid.size_vox[1], plane = W * H;
  std::vector<std::int64_t> stack;
  for (std::int64_t k = 0; k < s.ct.grid.size_vox[2]; ++k) {
    const std::int64_t o = k * plane;
    for (std::int64_t q = 0; q < plane; ++q)
      if (s.ref.labels[std::size_t(o + q)] && s.ct.hu[std::size_t(o + q)] < air_hu && !m.labels[std::size_t(o + q)]) {
        m.labels[std::size_t(o + q)] = 1;
        stack.push_back(q);
      }
    while (!stack.empty()) {  // flood the slice's air from the reference's air pixels
      const std::int64_t q = stack.back();
      stack.pop_back();
      const std::int64_t x = q % W, y = q / W;
      for (const auto [dx, dy] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
        const std::int64_t nx = x + dx, ny = y + dy, n = ny * W + nx;
        if (nx < 0 || ny < 0 || nx >= W || ny >= H || m.labels[std::size_t(o + n)] || !(s.ct.hu[std::size_t(o + n)] < air_hu))
          continue;
        m.labels[std::size_t(o + n)] = 1;
        stack.push_back(n);
      }
    }
  }
  return m;
}

SegmentOptions sweep_segment_options() {
  SegmentOptions o;
  if (const char* t = std::getenv("ORGANSMITH_SWEEP_PRESETS")) o.preset_overrides_toml = t;
  return o;
}

}  // namespace organsmith::testing
