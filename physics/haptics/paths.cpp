// Over 400 lines: the three guidance paths (centreline as a minimal path, incision over the
// rings, dissection along the liver bed) and the one path file format they are read and written
// in.
#include "physics/haptics/paths.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "core/format.h"
#include "core/vtk_xml.h"
#include "physics/haptics/contact.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numbers>
#include <queue>
#include <sstream>
#include <unordered_map>

namespace organsmith::physics {

namespace fs = std::filesystem;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// Point at arc length s of an open polyline with cumulative lengths `cum` (clamped to the ends).
Eigen::Vector3d point_at(const std::vector<Eigen::Vector3d>& p, const std::vector<double>& cum, double s) {
  if (s <= 0.0) return p.front();
  if (s >= cum.back()) return p.back();
  const auto it = std::upper_bound(cum.begin(), cum.end(), s);
  const std::size_t i = std::size_t(it - cum.begin()) - 1;
  const double len = cum[i + 1] - cum[i];
  const double f = len > 0 ? (s - cum[i]) / len : 0.0;
  return p[i] + f * (p[i + 1] - p[i]);
}

/// Exact 1-D squared distance transform (lower envelope of parabolas) of f sampled every h mm.
void edt_1d(const double* f, double* d, int n, double h, std::vector<int>& v, std::vector<double>& z) {
  v.resize(std::size_t(n));
  z.resize(std::size_t(n) + 1);
  int k = 0;
  int first = -1;
  for (int q = 0; q < n; ++q)
    if (std::isfinite(f[q])) {
      first = q;
      break;
    }
  if (first < 0) {
    for (int q = 0; q < n; ++q) d[q] = kInf;
    return;
  }
  v[0] = first;
  z[0] = -kInf;
  z[1] = kInf;
  for (int q = first + 1; q < n; ++q) {
    if (!std::isfinite(f[q])) continue;
    double s;
    while (true) {
      const double xq = q * h, xv = v[std::size_t(k)] * h;
      s = ((f[q] + xq * xq) - (f[v[std::size_t(k)]] + xv * xv)) / (2.0 * (xq - xv));
      if (s <= z[std::size_t(k)] && k > 0) {
        --k;
        continue;
      }
      break;
    }
    ++k;
    v[std::size_t(k)] = q;
    z[std::size_t(k)] = s;
    z[std::size_t(k) + 1] = kInf;
  }
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[std::size_t(k) + 1] < q * h) ++k;
    const double dx = (q - v[std::size_t(k)]) * h;
    d[q] = dx * dx + f[v[std::size_t(k)]];
  }
}

/// A cropped binary mask with one voxel of background padding on every side.
struct Crop {
  std::array<std::int64_t, 3> lo{};  ///< image index of crop index (0, 0, 0)
  std::array<int, 3> n{};
  std::vector<std::uint8_t> mask;
  std::size_t at(int a, int b, int c) const { return (std::size_t(c) * std::size_t(n[1]) + std::size_t(b)) * std::size_t(n[0]) + std::size_t(a); }
  bool inside(int a, int b, int c) const { return a >= 0 && b >= 0 && c >= 0 && a < n[0] && b < n[1] && c < n[2]; }
};

/// Trilinear interpolation of a crop-sized field at crop continuous index x (0 outside).
template <class T>
double trilinear(const Crop& cr, const std::vector<T>& f, const Eigen::Vector3d& x) {
  const int a0 = int(std::floor(x.x())), b0 = int(std::floor(x.y())), c0 = int(std::floor(x.z()));
  const double fa = x.x() - a0, fb = x.y() - b0, fc = x.z() - c0;
  double s = 0.0;
  for (int dc = 0; dc < 2; ++dc)
    for (int db = 0; db < 2; ++db)
      for (int da = 0; da < 2; ++da) {
        const int a = a0 + da, b = b0 + db, c = c0 + dc;
        if (!cr.inside(a, b, c)) continue;
        const double w = (da ? fa : 1 - fa) * (db ? fb : 1 - fb) * (dc ? fc : 1 - fc);
        s += w * double(f[cr.at(a, b, c)]);
      }
  return s;
}

}  // namespace

// ---- polylines -----------------------------------------------------------------------------------

Polyline resample_polyline(const Polyline& line, double spacing_mm) {
  if (line.points_lps_mm.empty()) throw InputError(ExitCode::unsupported_input, "cannot resample an empty path", {});
  if (!(spacing_mm > 0)) throw UsageError("the path spacing must be positive (mm)");
  std::vector<Eigen::Vector3d> p = line.points_lps_mm;
  if (line.closed && p.size() > 2) p.push_back(p.front());
  std::vector<double> cum(p.size(), 0.0);
  for (std::size_t i = 1; i < p.size(); ++i) cum[i] = cum[i - 1] + (p[i] - p[i - 1]).norm();
  Polyline out;
  out.name = line.name;
  out.closed = line.closed;
  const double L = cum.back();
  if (!(L > 0)) {
    out.points_lps_mm = {p.front()};
    return out;
  }
  const int n = std::max(1, int(std::lround(L / spacing_mm)));
  const int count = line.closed ? n : n + 1;
  for (int i = 0; i < count; ++i) out.points_lps_mm.push_back(point_at(p, cum, L * i / n));
  return out;
}

Polyline smooth_polyline(const Polyline& line, double sigma_mm) {
  Polyline out = line;
  const auto& p = line.points_lps_mm;
  const int n = int(p.size());
  if (n < 3 || !(sigma_mm > 0)) return out;
  double step = 0.0;
  for (int i = 1; i < n; ++i) step += (p[std::size_t(i)] - p[std::size_t(i - 1)]).norm();
  step /= (n - 1);
  if (!(step > 0)) return out;
  const double s = sigma_mm / step;
  const int half = std::max(1, int(std::ceil(3.0 * s)));
  std::vector<double> w(std::size_t(2 * half + 1));
  double sum = 0;
  for (int k = -half; k <= half; ++k) sum += w[std::size_t(k + half)] = std::exp(-0.5 * k * k / (s * s));
  for (auto& x : w) x /= sum;
  auto sample = [&](int i) -> Eigen::Vector3d {
    if (line.closed) return p[std::size_t(((i % n) + n) % n)];
    // Odd reflection about the end points: keeps them fixed and straight ends straight.
    if (i < 0) {
      const int j = std::min(-i, n - 1);
      return 2.0 * p.front() - p[std::size_t(j)];
    }
    if (i >= n) {
      const int j = std::max(2 * (n - 1) - i, 0);
      return 2.0 * p.back() - p[std::size_t(j)];
    }
    return p[std::size_t(i)];
  };
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d acc = Eigen::Vector3d::Zero();
    for (int k = -half; k <= half; ++k) acc += w[std::size_t(k + half)] * sample(i + k);
    out.points_lps_mm[std::size_t(i)] = acc;
  }
  if (!line.closed) out.points_lps_mm.front() = p.front(), out.points_lps_mm.back() = p.back();
  return out;
}

// ---- centreline ----------------------------------------------------------------------------------

Centerline trachea_centerline(const LabelMap& labels, const CenterlineOptions& o) {
  const ImageGrid& g = labels.grid;
  if (o.label == 0)
    throw UsageError("the centreline needs the lumen's label (0 is background)", "give CenterlineOptions::label");
  const std::string& organ = o.organ;
  // Bounding box of the label.
  std::array<std::int64_t, 3> lo{g.size_vox[0], g.size_vox[1], g.size_vox[2]}, hi{-1, -1, -1};
  std::int64_t count = 0;
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j) {
      const std::uint8_t* row = labels.labels.data() + g.offset(0, j, k);
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
        if (row[i] == o.label) {
          ++count;
          lo = {std::min(lo[0], i), std::min(lo[1], j), std::min(lo[2], k)};
          hi = {std::max(hi[0], i), std::max(hi[1], j), std::max(hi[2], k)};
        }
    }
  if (count < 27)
    throw InputError(ExitCode::mesh_input, "the " + organ + " lumen (label " + std::to_string(o.label) +
                                               ") is absent or too small for a centreline", {},
                     "check the segmentation of the " + organ);
  Crop cr;
  for (int a = 0; a < 3; ++a) {
    cr.lo[std::size_t(a)] = lo[std::size_t(a)] - 1;
    cr.n[std::size_t(a)] = int(hi[std::size_t(a)] - lo[std::size_t(a)] + 3);
  }
  const std::size_t N = std::size_t(cr.n[0]) * std::size_t(cr.n[1]) * std::size_t(cr.n[2]);
  cr.mask.assign(N, 0);
  for (int c = 1; c + 1 < cr.n[2]; ++c)
    for (int b = 1; b + 1 < cr.n[1]; ++b)
      for (int a = 1; a + 1 < cr.n[0]; ++a)
        cr.mask[cr.at(a, b, c)] = labels.at(cr.lo[0] + a, cr.lo[1] + b, cr.lo[2] + c) == o.label;
  // Largest 26-connected part.
  {
    std::vector<std::int32_t> comp(N, -1);
    std::vector<std::size_t> sizes, stack;
    for (std::size_t s = 0; s < N; ++s) {
      if (!cr.mask[s] || comp[s] >= 0) continue;
      const auto id = std::int32_t(sizes.size());
      std::size_t size = 0;
      stack.assign(1, s);
      comp[s] = id;
      while (!stack.empty()) {
        const std::size_t u = stack.back();
        stack.pop_back();
        ++size;
        const int a = int(u % std::size_t(cr.n[0])), b = int((u / std::size_t(cr.n[0])) % std::size_t(cr.n[1])),
                  c = int(u / (std::size_t(cr.n[0]) * std::size_t(cr.n[1])));
        for (int dc = -1; dc <= 1; ++dc)
          for (int db = -1; db <= 1; ++db)
            for (int da = -1; da <= 1; ++da) {
              if (!cr.inside(a + da, b + db, c + dc)) continue;
              const std::size_t v = cr.at(a + da, b + db, c + dc);
              if (cr.mask[v] && comp[v] < 0) comp[v] = id, stack.push_back(v);
            }
      }
      sizes.push_back(size);
    }
    const auto best = std::int32_t(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
    for (std::size_t s = 0; s < N; ++s) cr.mask[s] = comp[s] == best;
  }
  // Distance to the wall (nearest background voxel centre), mm: separable exact EDT.
  std::vector<double> dist(N);
  for (std::size_t s = 0; s < N; ++s) dist[s] = cr.mask[s] ? kInf : 0.0;
  {
    std::vector<int> v;
    std::vector<double> z, f, d;
    for (int axis = 0; axis < 3; ++axis) {
      const int n = cr.n[std::size_t(axis)];
      f.resize(std::size_t(n));
      d.resize(std::size_t(n));
      const double h = g.spacing_mm[axis];
      const int o1 = (axis + 1) % 3, o2 = (axis + 2) % 3;
      for (int y = 0; y < cr.n[std::size_t(o2)]; ++y)
        for (int x = 0; x < cr.n[std::size_t(o1)]; ++x) {
          auto idx = [&](int t) {
            std::array<int, 3> c{};
            c[std::size_t(axis)] = t;
            c[std::size_t(o1)] = x;
            c[std::size_t(o2)] = y;
            return cr.at(c[0], c[1], c[2]);
          };
          for (int t = 0; t < n; ++t) f[std::size_t(t)] = dist[idx(t)];
          edt_1d(f.data(), d.data(), n, h, v, z);
          for (int t = 0; t < n; ++t) dist[idx(t)] = d[std::size_t(t)];
        }
    }
    for (auto& x : dist) x = std::sqrt(x);
  }
  auto crop_to_lps = [&](double a, double b, double c) {
    return g.index_to_lps_mm(Eigen::Vector3d(double(cr.lo[0]) + a, double(cr.lo[1]) + b, double(cr.lo[2]) + c));
  };
  // Principal axis of the lumen, and the grid axis most aligned with it: its first and last
  // planes holding lumen voxels are the end caps.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  std::size_t nvox = 0;
  for (int c = 0; c < cr.n[2]; ++c)
    for (int b = 0; b < cr.n[1]; ++b)
      for (int a = 0; a < cr.n[0]; ++a)
        if (cr.mask[cr.at(a, b, c)]) mean += crop_to_lps(a, b, c), ++nvox;
  mean /= double(nvox);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int c = 0; c < cr.n[2]; ++c)
    for (int b = 0; b < cr.n[1]; ++b)
      for (int a = 0; a < cr.n[0]; ++a)
        if (cr.mask[cr.at(a, b, c)]) {
          const Eigen::Vector3d d = crop_to_lps(a, b, c) - mean;
          cov += d * d.transpose();
        }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  Eigen::Vector3d axis_lps = es.eigenvectors().col(2);
  if (axis_lps.z() < 0) axis_lps = -axis_lps;  // toward superior (cranial)
  int grid_axis = 0;
  double best_align = -1;
  for (int a = 0; a < 3; ++a) {
    const Eigen::Vector3d dir = g.index_to_lps_mm(Eigen::Vector3d::Unit(a)) - g.index_to_lps_mm(Eigen::Vector3d::Zero());
    const double al = std::abs(dir.normalized().dot(axis_lps));
    if (al > best_align) best_align = al, grid_axis = a;
  }
  int plane_min = std::numeric_limits<int>::max(), plane_max = -1;
  for (int c = 0; c < cr.n[2]; ++c)
    for (int b = 0; b < cr.n[1]; ++b)
      for (int a = 0; a < cr.n[0]; ++a)
        if (cr.mask[cr.at(a, b, c)]) {
          const int t = std::array<int, 3>{a, b, c}[std::size_t(grid_axis)];
          plane_min = std::min(plane_min, t);
          plane_max = std::max(plane_max, t);
        }
  auto cap_voxel = [&](int plane) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    std::vector<std::size_t> cap;
    for (int c = 0; c < cr.n[2]; ++c)
      for (int b = 0; b < cr.n[1]; ++b)
        for (int a = 0; a < cr.n[0]; ++a)
          if (cr.mask[cr.at(a, b, c)] && std::array<int, 3>{a, b, c}[std::size_t(grid_axis)] == plane) {
            cap.push_back(cr.at(a, b, c));
            centroid += Eigen::Vector3d(a, b, c);
          }
    centroid /= double(cap.size());
    std::size_t best = cap.front();
    double bd = kInf;
    for (auto s : cap) {
      const Eigen::Vector3d x(double(s % std::size_t(cr.n[0])), double((s / std::size_t(cr.n[0])) % std::size_t(cr.n[1])),
                              double(s / (std::size_t(cr.n[0]) * std::size_t(cr.n[1]))));
      const double d = (x - centroid).cwiseProduct(g.spacing_mm).squaredNorm();
      if (d < bd) bd = d, best = s;
    }
    return best;
  };
  std::size_t cap_a = cap_voxel(plane_min), cap_b = cap_voxel(plane_max);
  // Which cap is cranial: the one further along the (superior-pointing) axis.
  auto pos = [&](std::size_t s) {
    return crop_to_lps(double(s % std::size_t(cr.n[0])), double((s / std::size_t(cr.n[0])) % std::size_t(cr.n[1])),
                       double(s / (std::size_t(cr.n[0]) * std::size_t(cr.n[1]))));
  };
  if ((pos(cap_a) - pos(cap_b)).dot(axis_lps) < 0) std::swap(cap_a, cap_b);
  // Minimal path under the medialness cost (Dijkstra, 26-neighbourhood).
  std::vector<double> cost(N, kInf);
  std::vector<std::int64_t> prev(N, -1);
  using Item = std::pair<double, std::size_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> heap;
  auto weight = [&](std::size_t s) { return 1.0 / std::pow(dist[s] + 0.1, o.medial_power); };
  cost[cap_a] = 0;
  heap.push({0.0, cap_a});
  while (!heap.empty()) {
    const auto [cu, u] = heap.top();
    heap.pop();
    if (cu > cost[u]) continue;
    if (u == cap_b) break;
    const int a = int(u % std::size_t(cr.n[0])), b = int((u / std::size_t(cr.n[0])) % std::size_t(cr.n[1])),
              c = int(u / (std::size_t(cr.n[0]) * std::size_t(cr.n[1])));
    for (int dc = -1; dc <= 1; ++dc)
      for (int db = -1; db <= 1; ++db)
        for (int da = -1; da <= 1; ++da) {
          if ((da | db | dc) == 0 || !cr.inside(a + da, b + db, c + dc)) continue;
          const std::size_t v = cr.at(a + da, b + db, c + dc);
          if (!cr.mask[v]) continue;
          const double len = Eigen::Vector3d(da, db, dc).cwiseProduct(g.spacing_mm).norm();
          const double cv = cu + len * 0.5 * (weight(u) + weight(v));
          if (cv < cost[v]) cost[v] = cv, prev[v] = std::int64_t(u), heap.push({cv, v});
        }
  }
  if (!std::isfinite(cost[cap_b]))
    throw InputError(ExitCode::mesh_input, "the " + organ + " lumen's ends are not connected", {});
  Polyline raw;
  raw.name = organ + "_centerline";
  for (std::int64_t s = std::int64_t(cap_b); s >= 0; s = prev[std::size_t(s)]) raw.points_lps_mm.push_back(pos(std::size_t(s)));
  std::reverse(raw.points_lps_mm.begin(), raw.points_lps_mm.end());  // cranial → caudal
  Polyline fine = raw.points_lps_mm.size() >= 2 ? resample_polyline(raw, 0.25) : raw;
  fine = smooth_polyline(fine, o.smoothing_mm);
  // Extend both ends along their tangents to the lumen boundary (occupancy 0.5).
  std::vector<float> occ(N);
  for (std::size_t s = 0; s < N; ++s) occ[s] = cr.mask[s] ? 1.f : 0.f;
  auto to_crop = [&](const Eigen::Vector3d& p) {
    return Eigen::Vector3d(g.lps_mm_to_index(p) - Eigen::Vector3d(double(cr.lo[0]), double(cr.lo[1]), double(cr.lo[2])));
  };
  Centerline out;
  auto& fp = fine.points_lps_mm;
  for (int end = 0; end < 2; ++end) {
    if (fp.size() < 2) break;
    const Eigen::Vector3d e = end == 0 ? fp.front() : fp.back();
    // Tangent over the last 3 mm (or the whole line when shorter).
    std::vector<double> cum(fp.size(), 0.0);
    for (std::size_t i = 1; i < fp.size(); ++i) cum[i] = cum[i - 1] + (fp[i] - fp[i - 1]).norm();
    const double back = std::min(3.0, cum.back());
    const Eigen::Vector3d inner = end == 0 ? point_at(fp, cum, back) : point_at(fp, cum, cum.back() - back);
    Eigen::Vector3d t = e - inner;
    if (!(t.norm() > 0)) break;
    t.normalize();
    const double step = 0.02;
    double s = 0.0, prev_occ = trilinear(cr, occ, to_crop(e));
    double reach = 0.0;
    for (int i = 1; i <= 2000; ++i) {
      const double oc = trilinear(cr, occ, to_crop(e + (i * step) * t));
      if (oc < 0.5) {
        const double f = (prev_occ - 0.5) / std::max(prev_occ - oc, 1e-12);
        reach = s + f * step;
        break;
      }
      s = i * step;
      prev_occ = oc;
    }
    out.end_extension_mm[std::size_t(end)] = reach;
    if (reach > 0) {
      if (end == 0) fp.insert(fp.begin(), e + reach * t);
      else fp.push_back(e + reach * t);
    }
  }
  out.line = resample_polyline(fine, o.spacing_mm);
  out.line.name = organ + "_centerline";
  for (const auto& p : out.line.points_lps_mm) out.radius_mm.push_back(trilinear(cr, dist, to_crop(p)));
  return out;
}

// ---- incision ------------------------------------------------------------------------------------

IncisionPath trachea_incision_path(const Centerline& cl, const SurfaceIndex& wall, const IncisionOptions& o) {
  if (o.first_ring < 1 || o.ring_count < 1 || !(o.ring_pitch_mm > 0) || !(o.spacing_mm > 0))
    throw UsageError("incision: first ring and ring count must be ≥ 1, pitch and spacing positive");
  const auto& p = cl.line.points_lps_mm;
  if (p.size() < 2) throw InputError(ExitCode::mesh_input, "the trachea centreline has fewer than 2 points", {});
  std::vector<double> cum(p.size(), 0.0);
  for (std::size_t i = 1; i < p.size(); ++i) cum[i] = cum[i - 1] + (p[i] - p[i - 1]).norm();
  IncisionPath out;
  out.first_ring = o.first_ring;
  out.last_ring = o.first_ring + o.ring_count - 1;
  out.start_arc_mm = (o.first_ring - 1) * o.ring_pitch_mm;
  out.end_arc_mm = out.start_arc_mm + o.ring_count * o.ring_pitch_mm;
  if (out.end_arc_mm > cum.back())
    throw InputError(ExitCode::mesh_input,
                     "the incision (rings " + std::to_string(out.first_ring) + "–" + std::to_string(out.last_ring) +
                         ", to " + format_fixed(out.end_arc_mm, 1) + " mm) runs beyond the trachea centreline (" +
                         format_fixed(cum.back(), 1) + " mm)",
                     {}, "choose fewer rings or an earlier first ring");
  const Eigen::Vector3d ant = o.anterior_lps.normalized();
  Polyline hits;
  hits.name = "trachea_incision";
  const int n = std::max(1, int(std::lround((out.end_arc_mm - out.start_arc_mm) / (0.5 * o.spacing_mm))));
  for (int i = 0; i <= n; ++i) {
    const double s = out.start_arc_mm + (out.end_arc_mm - out.start_arc_mm) * i / n;
    const Eigen::Vector3d c = point_at(p, cum, s);
    Eigen::Vector3d t = point_at(p, cum, s + 1.0) - point_at(p, cum, s - 1.0);
    t.normalize();
    Eigen::Vector3d a = ant - ant.dot(t) * t;
    if (!(a.norm() > 1e-6)) throw InputError(ExitCode::mesh_input, "the trachea runs along the anterior direction", {});
    a.normalize();
    constexpr double far_mm = 80.0;
    const auto h = wall.first_hit(c + far_mm * a, -a, far_mm);
    if (!h || h->surface != 0)
      throw InputError(ExitCode::mesh_input,
                       "the anterior ray at " + format_fixed(s, 1) + " mm along the centreline misses the trachea wall", {},
                       "check that the wall surface belongs to this trachea");
    hits.points_lps_mm.push_back(h->point_lps_mm);
  }
  out.line = resample_polyline(hits, o.spacing_mm);
  for (auto& q : out.line.points_lps_mm) {
    const ClosestPoint cp = wall.closest(q, 2.0);
    if (cp.found && cp.surface == 0) q = cp.point_lps_mm;
  }
  const auto& l = out.line.points_lps_mm;
  for (std::size_t i = 0; i < l.size(); ++i) {
    out.max_wall_distance_mm = std::max(out.max_wall_distance_mm, std::abs(wall.closest(l[i]).signed_distance_mm));
    if (i + 1 < l.size())
      out.max_wall_distance_mm =
          std::max(out.max_wall_distance_mm, std::abs(wall.closest(0.5 * (l[i] + l[i + 1])).signed_distance_mm));
  }
  out.length_mm = out.line.length_mm();
  return out;
}

// ---- files ---------------------------------------------------------------------------------------

Polyline read_path_file(const fs::path& path) {
  return read_path_text(read_input_file(path, "the path file", ExitCode::unsupported_input,
                                        "a path is a CSV with columns x,y,z (LPS mm) or JSON {\"points_lps_mm\": [[x, y, z], …]}"),
                        path);
}

Polyline read_path_text(const std::string& text, const fs::path& path) {
  Polyline out;
  out.name = path.stem().string();
  const auto bad = [&](const std::string& what, const std::string& hint = {}) {
    return InputError(ExitCode::unsupported_input, what, path,
                      hint.empty() ? "a path is a CSV with columns x,y,z (LPS mm) or JSON {\"points_lps_mm\": [[x, y, z], …]}"
                                   : hint);
  };
  const auto first = text.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && (text[first] == '{' || text[first] == '[')) {
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception& e) {
      throw bad(std::string("not valid JSON: ") + e.what());
    }
    const nlohmann::json* pts = &j;
    if (j.is_object()) {
      if (!j.contains("points_lps_mm")) throw bad("the JSON has no \"points_lps_mm\" array");
      pts = &j["points_lps_mm"];
      out.closed = j.value("closed", false);
      out.name = j.value("name", out.name);
    }
    if (!pts->is_array()) throw bad("the points are not an array");
    for (std::size_t i = 0; i < pts->size(); ++i) {
      const auto& p = (*pts)[i];
      if (!p.is_array() || p.size() != 3 || !p[0].is_number() || !p[1].is_number() || !p[2].is_number())
        throw bad("point " + std::to_string(i) + " is not three numbers [x, y, z]");
      out.points_lps_mm.emplace_back(p[0].get<double>(), p[1].get<double>(), p[2].get<double>());
    }
  } else {
    std::istringstream ls(text);
    std::string line;
    int lineno = 0;
    std::array<int, 3> col{-1, -1, -1};
    std::size_t ncols = 0;
    auto split = [](const std::string& s) {
      std::vector<std::string> f;
      std::string cur;
      for (char ch : s) {
        if (ch == ',') f.push_back(cur), cur.clear();
        else if (ch != '\r') cur += ch;
      }
      f.push_back(cur);
      for (auto& x : f) {
        const auto a = x.find_first_not_of(" \t"), b = x.find_last_not_of(" \t");
        x = a == std::string::npos ? "" : x.substr(a, b - a + 1);
      }
      return f;
    };
    while (std::getline(ls, line)) {
      ++lineno;
      if (line.find_first_not_of(" \t\r") == std::string::npos || line[line.find_first_not_of(" \t")] == '#') continue;
      auto f = split(line);
      if (ncols == 0) {
        ncols = f.size();
        for (std::size_t c = 0; c < f.size(); ++c) {
          std::string n = f[c];
          std::transform(n.begin(), n.end(), n.begin(), [](unsigned char ch) { return char(std::tolower(ch)); });
          for (int a = 0; a < 3; ++a) {
            const std::string base(1, "xyz"[a]);
            if (n == base || n == base + "_mm" || n == base + "_lps_mm") col[std::size_t(a)] = int(c);
          }
        }
        if (col[0] < 0 || col[1] < 0 || col[2] < 0)
          throw bad("line " + std::to_string(lineno) + ": the header names no x, y, z columns");
        continue;
      }
      if (f.size() != ncols)
        throw bad("line " + std::to_string(lineno) + ": " + std::to_string(f.size()) + " fields, the header has " +
                  std::to_string(ncols));
      Eigen::Vector3d p;
      for (int a = 0; a < 3; ++a) {
        const std::string& s = f[std::size_t(col[std::size_t(a)])];
        char* end = nullptr;
        const double v = std::strtod(s.c_str(), &end);
        if (s.empty() || end != s.c_str() + s.size() || !std::isfinite(v))
          throw bad("line " + std::to_string(lineno) + ": '" + s + "' is not a finite number (column " + "xyz"[a] + ")");
        p[a] = v;
      }
      out.points_lps_mm.push_back(p);
    }
  }
  for (std::size_t i = 0; i < out.points_lps_mm.size(); ++i)
    if (!out.points_lps_mm[i].allFinite()) throw bad("point " + std::to_string(i) + " has a non-finite coordinate");
  if (out.points_lps_mm.size() < 2)
    throw bad("the path has " + std::to_string(out.points_lps_mm.size()) + " point(s); at least 2 are needed");
  if (!(out.length_mm() > 0)) throw bad("the path has zero length (all points coincide)");
  return out;
}

void check_path_within(const Polyline& path, const ImageGrid& g, const fs::path& source, double tol) {
  for (std::size_t i = 0; i < path.points_lps_mm.size(); ++i) {
    const Eigen::Vector3d x = g.lps_mm_to_index(path.points_lps_mm[i]);
    for (int a = 0; a < 3; ++a) {
      const double margin = 0.5 + tol / g.spacing_mm[a];
      if (x[a] < -margin || x[a] > double(g.size_vox[std::size_t(a)] - 1) + margin) {
        const auto& p = path.points_lps_mm[i];
        throw InputError(ExitCode::unsupported_input,
                         "point " + std::to_string(i) + " of the path (" + format_fixed(p.x(), 1) + ", " + format_fixed(p.y(), 1) +
                             ", " + format_fixed(p.z(), 1) + " mm) lies outside the image, far from the body",
                         source, "paths are in LPS millimetres, the coordinates of the CT (see `organsmith info`)");
      }
    }
  }
}

std::string path_json(const Polyline& path, const std::vector<std::pair<std::string, double>>& properties,
                      const std::vector<std::pair<std::string, std::string>>& notes) {
  const auto& p = path.points_lps_mm;
  std::vector<double> s = path.arc_length_mm();
  std::string j = "{\n  \"name\": " + nlohmann::json(path.name).dump() + ",\n  \"coordinates\": \"LPS mm\",\n";
  j += "  \"closed\": " + std::string(path.closed ? "true" : "false") + ",\n";
  j += "  \"length_mm\": " + format_fixed(path.length_mm(), 4) + ",\n  \"point_count\": " + std::to_string(p.size()) + ",\n";
  j += "  \"properties\": {";
  for (std::size_t i = 0; i < properties.size(); ++i)
    j += (i ? ", " : "") + nlohmann::json(properties[i].first).dump() + ": " + format_g(properties[i].second, 6);
  j += "},\n";
  if (!notes.empty()) {
    j += "  \"notes\": {";
    for (std::size_t i = 0; i < notes.size(); ++i)
      j += (i ? ", " : "") + nlohmann::json(notes[i].first).dump() + ": " + nlohmann::json(notes[i].second).dump();
    j += "},\n";
  }
  j += "  \"points_lps_mm\": [";
  for (std::size_t i = 0; i < p.size(); ++i)
    j += std::string(i ? ",\n    " : "\n    ") + "[" + format_fixed(p[i].x(), 4) + ", " + format_fixed(p[i].y(), 4) + ", " + format_fixed(p[i].z(), 4) + "]";
  j += "\n  ],\n  \"arc_length_mm\": [";
  for (std::size_t i = 0; i < s.size(); ++i) j += (i ? ", " : "") + format_fixed(s[i], 4);
  j += "]\n}\n";
  return j;
}

std::string path_vtp(const Polyline& path) {
  const auto& p = path.points_lps_mm;
  VtkPiece piece;
  piece.points = p;
  piece.point_decimals = 4;  // 0.1 µm: far below the 1 mm sampling
  if (!p.empty()) {
    std::vector<std::int64_t> ids(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) ids[i] = std::int64_t(i);
    if (path.closed && p.size() > 2) ids.push_back(0);
    piece.add_cell(ids);
  }
  piece.point_data.push_back({"arc_length_mm", "Float64", 1, path.arc_length_mm(), 4});
  return vtk_polydata_xml(piece, VtkPolyCells::lines, "organsmith guidance path '" + path.name + "', LPS mm");
}

}  // namespace organsmith::physics
