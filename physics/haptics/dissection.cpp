// Over 400 lines: the liver bed found in the CT (crop, smoothing, intensity survey, opening,
// connected region, probes) and the dissection path (bed score from any source, smoothing over
// the surface, the iso-line, its curve shortening along the surface, its checks) are one method in
// two halves sharing the surface's vertex normals and score field. Its second user (the solver
// model's fixed liver bed) takes the score through `liver_bed_score`, so the two agree on where the
// bed is.
#include "physics/haptics/dissection.h"

#include "core/errors.h"
#include "core/format.h"
#include "physics/haptics/contact.h"
#include "physics/haptics/paths.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <numbers>

namespace organsmith::physics {

namespace {

/// A box of the CT around the organ, smoothed, with index ↔ position helpers.
struct Crop {
  ImageGrid grid;                   // the CT's grid (positions)
  std::array<std::int64_t, 3> lo{}, n{};
  std::vector<float> v;             // smoothed HU, i fastest

  std::int64_t at(std::int64_t i, std::int64_t j, std::int64_t k) const { return i + n[0] * (j + n[1] * k); }
  /// Continuous crop index of a position.
  Eigen::Vector3d index(const Eigen::Vector3d& p) const {
    return grid.lps_mm_to_index(p) - Eigen::Vector3d(double(lo[0]), double(lo[1]), double(lo[2]));
  }
  /// Trilinear value; NaN outside the crop.
  double sample(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d x = index(p);
    std::int64_t c[3];
    double f[3];
    for (int a = 0; a < 3; ++a) {
      if (!(x[a] >= 0.0 && x[a] <= double(n[std::size_t(a)] - 1))) return std::numeric_limits<double>::quiet_NaN();
      c[a] = std::min<std::int64_t>(std::int64_t(x[a]), n[std::size_t(a)] - 2 < 0 ? 0 : n[std::size_t(a)] - 2);
      f[a] = n[std::size_t(a)] > 1 ? x[a] - double(c[a]) : 0.0;
    }
    double s = 0.0;
    for (int dz = 0; dz < 2; ++dz)
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          const std::int64_t i = std::min(c[0] + dx, n[0] - 1), j = std::min(c[1] + dy, n[1] - 1),
                             k = std::min(c[2] + dz, n[2] - 1);
          s += (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]) * double(v[std::size_t(at(i, j, k))]);
        }
    return s;
  }
  /// Nearest voxel's crop offset; −1 outside.
  std::int64_t nearest(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d x = index(p);
    std::int64_t c[3];
    for (int a = 0; a < 3; ++a) {
      c[a] = std::int64_t(std::lround(x[a]));
      if (!std::isfinite(x[a]) || c[a] < 0 || c[a] >= n[std::size_t(a)]) return -1;
    }
    return at(c[0], c[1], c[2]);
  }
};

/// Separable Gaussian along axis `a` (σ in voxels), edges clamped.
void blur_axis(std::vector<float>& v, const std::array<std::int64_t, 3>& n, int a, double sigma) {
  if (sigma < 0.3 || n[std::size_t(a)] < 2) return;
  const int r = int(std::ceil(3.0 * sigma));
  std::vector<double> w(std::size_t(2 * r + 1));
  double sum = 0;
  for (int t = -r; t <= r; ++t) sum += w[std::size_t(t + r)] = std::exp(-0.5 * t * t / (sigma * sigma));
  for (auto& x : w) x /= sum;
  const std::int64_t stride = a == 0 ? 1 : a == 1 ? n[0] : n[0] * n[1];
  const std::int64_t len = n[std::size_t(a)];
  std::vector<float> line(static_cast<std::size_t>(len));
  for (std::int64_t base = 0; base < n[0] * n[1] * n[2]; ++base) {
    // `base` runs over the lines' first voxels: its coordinate along `a` must be 0.
    const std::int64_t coord = (base / stride) % len;
    if (coord != 0) continue;
    for (std::int64_t t = 0; t < len; ++t) line[std::size_t(t)] = v[std::size_t(base + t * stride)];
    for (std::int64_t t = 0; t < len; ++t) {
      double s = 0;
      for (int d = -r; d <= r; ++d) s += w[std::size_t(d + r)] * line[std::size_t(std::clamp<std::int64_t>(t + d, 0, len - 1))];
      v[std::size_t(base + t * stride)] = float(s);
    }
  }
}

/// Binary erosion (or dilation) by a box of half-widths r along each axis, separable; outside
/// the crop counts as background for erosion.
std::vector<char> box_filter(const std::vector<char>& in, const std::array<std::int64_t, 3>& n,
                             const std::array<int, 3>& r, bool erode) {
  std::vector<char> cur = in, next(in.size());
  for (int a = 0; a < 3; ++a) {
    if (r[std::size_t(a)] == 0) continue;
    const std::int64_t stride = a == 0 ? 1 : a == 1 ? n[0] : n[0] * n[1];
    const std::int64_t len = n[std::size_t(a)];
    for (std::int64_t o = 0; o < std::int64_t(cur.size()); ++o) {
      const std::int64_t c = (o / stride) % len;
      bool out = erode;
      for (int d = -r[std::size_t(a)]; d <= r[std::size_t(a)]; ++d) {
        const std::int64_t t = c + d;
        const bool val = t >= 0 && t < len && cur[std::size_t(o + d * stride)];
        if (erode && !val) { out = false; break; }
        if (!erode && val) { out = true; break; }
      }
      next[std::size_t(o)] = char(out);
    }
    std::swap(cur, next);
  }
  return cur;
}

double median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

}  // namespace

std::vector<Eigen::Vector3d> vertex_normals(const SurfaceMesh& m) {
  const auto& V = m.vertices_lps_mm;
  std::vector<Eigen::Vector3d> n(V.size(), Eigen::Vector3d::Zero());
  for (const auto& t : m.triangles) {
    const Eigen::Vector3d a = (V[std::size_t(t[1])] - V[std::size_t(t[0])]).cross(V[std::size_t(t[2])] - V[std::size_t(t[0])]);
    for (auto i : t) n[std::size_t(i)] += a;
  }
  for (auto& x : n)
    if (x.norm() > 0) x.normalize();
  return n;
}

LiverBedEstimate liver_bed_from_ct(const SurfaceMesh& gb, const Volume& ct, const LiverBedOptions& o) {
  LiverBedEstimate out;
  const auto& V = gb.vertices_lps_mm;
  if (V.empty() || gb.triangles.empty()) {
    out.reason = "the gallbladder surface is empty";
    return out;
  }
  // The crop: the organ's box grown by the survey distance.
  Crop cr;
  cr.grid = ct.grid;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : V) {
    const Eigen::Vector3d x = ct.grid.lps_mm_to_index(p);
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  for (int a = 0; a < 3; ++a) {
    const double m = (o.survey_mm + 3.0) / ct.grid.spacing_mm[a];
    const std::int64_t size = ct.grid.size_vox[std::size_t(a)];
    const std::int64_t l = std::clamp<std::int64_t>(std::int64_t(std::floor(lo[a] - m)), 0, size - 1);
    const std::int64_t h = std::clamp<std::int64_t>(std::int64_t(std::ceil(hi[a] + m)), 0, size - 1);
    cr.lo[std::size_t(a)] = l;
    cr.n[std::size_t(a)] = h - l + 1;
  }
  cr.v.resize(std::size_t(cr.n[0] * cr.n[1] * cr.n[2]));
  for (std::int64_t k = 0; k < cr.n[2]; ++k)
    for (std::int64_t j = 0; j < cr.n[1]; ++j)
      for (std::int64_t i = 0; i < cr.n[0]; ++i)
        cr.v[std::size_t(cr.at(i, j, k))] = ct.at(cr.lo[0] + i, cr.lo[1] + j, cr.lo[2] + k);
  for (int a = 0; a < 3; ++a) blur_axis(cr.v, cr.n, a, o.smoothing_mm / ct.grid.spacing_mm[a]);

  const std::vector<Eigen::Vector3d> normal = vertex_normals(gb);
  // 1. bile inside, the surroundings' soft-tissue mode outside.
  std::vector<double> inside, around;
  for (std::size_t i = 0; i < V.size(); ++i) {
    if (normal[i].norm() == 0) continue;
    for (double d : {1.0, 1.75, 2.5})
      if (const double s = cr.sample(V[i] - d * normal[i]); std::isfinite(s)) inside.push_back(s);
    for (double d = 2.0; d <= o.survey_mm; d += 2.0)
      if (const double s = cr.sample(V[i] + d * normal[i]); std::isfinite(s)) around.push_back(s);
  }
  out.bile_hu = median(inside);
  if (!std::isfinite(out.bile_hu)) {
    out.reason = "the gallbladder surface lies outside the CT";
    return out;
  }
  // Histogram of the surroundings (2 HU bins from 50 HU below bile to 400 HU), smoothed; the liver
  // is its largest local maximum at least min_contrast_hu above bile (a maximum at the lower end of
  // that range is the tail of bile or of equally dark tissue, not a mode).
  const double h0 = out.bile_hu - 50.0, bin = 2.0;
  const int bins = std::max(3, int(std::ceil((400.0 - h0) / bin)));
  std::vector<double> hist(std::size_t(bins), 0.0), smooth(std::size_t(bins), 0.0);
  for (double s : around)
    if (s >= h0 && s < h0 + bins * bin) hist[std::size_t((s - h0) / bin)] += 1.0;
  for (int b = 0; b < bins; ++b)
    for (int d = -4; d <= 4; ++d)
      if (b + d >= 0 && b + d < bins) smooth[std::size_t(b)] += std::exp(-0.5 * d * d / 4.0) * hist[std::size_t(b + d)];
  int peak = -1;
  for (int b = 1; b + 1 < bins; ++b) {
    const double centre = h0 + (b + 0.5) * bin;
    if (centre < out.bile_hu + o.min_contrast_hu || smooth[std::size_t(b)] <= 0.0) continue;
    if (smooth[std::size_t(b)] < smooth[std::size_t(b - 1)] || smooth[std::size_t(b)] < smooth[std::size_t(b + 1)]) continue;
    if (peak < 0 || smooth[std::size_t(b)] > smooth[std::size_t(peak)]) peak = b;
  }
  if (peak < 0) {
    out.reason = "no tissue around the gallbladder is " + format_g(o.min_contrast_hu) + " HU or more brighter than bile (" +
                 format_g(std::round(out.bile_hu)) + " HU): the CT cannot tell the liver from bile";
    return out;
  }
  out.liver_hu = h0 + (peak + 0.5) * bin;
  std::vector<double> dev;
  for (double s : around)
    if (std::abs(s - out.liver_hu) <= 30.0) dev.push_back(std::abs(s - out.liver_hu));
  const double sd = 1.4826 * median(dev);
  const double w = std::max(o.band_min_hu, 2.5 * (std::isfinite(sd) ? sd : 0.0));
  out.band_lo_hu = std::max(out.liver_hu - w, 0.5 * (out.bile_hu + out.liver_hu));
  out.band_hi_hu = out.liver_hu + w;

  // 2. Parenchyma: the band, opened, and its largest connected region in the crop.
  std::vector<char> mask(cr.v.size());
  for (std::size_t i = 0; i < mask.size(); ++i) mask[i] = char(cr.v[i] >= out.band_lo_hu && cr.v[i] <= out.band_hi_hu);
  std::array<int, 3> r{};
  for (int a = 0; a < 3; ++a)
    r[std::size_t(a)] = std::max(0, int(std::lround(o.opening_mm / ct.grid.spacing_mm[a])));
  if (r[0] + r[1] + r[2] > 0) mask = box_filter(box_filter(mask, cr.n, r, true), cr.n, r, false);
  std::vector<std::int32_t> comp(mask.size(), 0);
  std::vector<std::int64_t> sizes{0};
  for (std::int64_t s = 0; s < std::int64_t(mask.size()); ++s) {
    if (!mask[std::size_t(s)] || comp[std::size_t(s)]) continue;
    const std::int32_t id = std::int32_t(sizes.size());
    std::int64_t count = 0;
    std::deque<std::int64_t> q{s};
    comp[std::size_t(s)] = id;
    while (!q.empty()) {
      const std::int64_t c = q.front();
      q.pop_front();
      ++count;
      const std::int64_t ci = c % cr.n[0], cj = (c / cr.n[0]) % cr.n[1], ck = c / (cr.n[0] * cr.n[1]);
      const std::int64_t nb[6][3] = {{ci - 1, cj, ck}, {ci + 1, cj, ck}, {ci, cj - 1, ck},
                                     {ci, cj + 1, ck}, {ci, cj, ck - 1}, {ci, cj, ck + 1}};
      for (const auto& x : nb) {
        if (x[0] < 0 || x[1] < 0 || x[2] < 0 || x[0] >= cr.n[0] || x[1] >= cr.n[1] || x[2] >= cr.n[2]) continue;
        const std::int64_t t = cr.at(x[0], x[1], x[2]);
        if (mask[std::size_t(t)] && !comp[std::size_t(t)]) {
          comp[std::size_t(t)] = id;
          q.push_back(t);
        }
      }
    }
    sizes.push_back(count);
  }
  const auto biggest = std::max_element(sizes.begin(), sizes.end());
  if (*biggest == 0) {
    out.reason = "no parenchyma of " + format_g(std::round(out.band_lo_hu)) + "–" + format_g(std::round(out.band_hi_hu)) + " HU lies around the gallbladder";
    return out;
  }
  const std::int32_t liver = std::int32_t(biggest - sizes.begin());
  out.liver_region_ml = double(*biggest) * ct.grid.spacing_mm.prod() / 1000.0;

  // 3. The probes.
  out.score.assign(V.size(), 0.0);
  const int probes = std::max(1, int(std::lround((o.probe_far_mm - o.probe_near_mm) / 0.5)) + 1);
  for (std::size_t i = 0; i < V.size(); ++i) {
    if (normal[i].norm() == 0) continue;
    int hits = 0;
    for (int p = 0; p < probes; ++p) {
      const double d = probes == 1 ? o.probe_near_mm : o.probe_near_mm + (o.probe_far_mm - o.probe_near_mm) * p / (probes - 1);
      const std::int64_t c = cr.nearest(V[i] + d * normal[i]);
      if (c >= 0 && comp[std::size_t(c)] == liver) ++hits;
    }
    out.score[i] = double(hits) / probes;
  }
  return out;
}


namespace {

/// Closest distance between segments [p0, p1] and [q0, q1].
double segment_distance(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0,
                        const Eigen::Vector3d& q1) {
  const Eigen::Vector3d d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0.0, t = 0.0;
  if (a <= 1e-18 && e <= 1e-18) return r.norm();
  if (a <= 1e-18) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-18) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), den = a * e - b * b;
      s = den > 1e-18 ? std::clamp((b * f - c * e) / den, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return ((p0 + s * d1) - (q0 + t * d2)).norm();
}

/// Bed flags from a liver label: a vertex with liver voxel centres within the reach.
std::vector<double> score_from_label(const SurfaceMesh& gb, const LabelMap& liver, const DissectionOptions& o) {
  const auto& V = gb.vertices_lps_mm;
  const ImageGrid& g = liver.grid;
  std::vector<double> bed(V.size(), 0.0);
  // Liver voxel centres lie up to about a voxel from the surface that touches them: on coarse
  // grids the reach grows with the voxel diagonal.
  const double reach_mm = std::max(o.bed_distance_mm, 0.75 * g.spacing_mm.norm());
  const Eigen::Vector3d r = (Eigen::Vector3d::Constant(reach_mm).cwiseQuotient(g.spacing_mm)).array().ceil();
  for (std::size_t i = 0; i < V.size(); ++i) {
    const Eigen::Vector3d x = g.lps_mm_to_index(V[i]);
    const Eigen::Vector3i c(int(std::lround(x.x())), int(std::lround(x.y())), int(std::lround(x.z())));
    for (int k = c.z() - int(r.z()); k <= c.z() + int(r.z()) && bed[i] == 0.0; ++k)
      for (int j = c.y() - int(r.y()); j <= c.y() + int(r.y()) && bed[i] == 0.0; ++j)
        for (int ii = c.x() - int(r.x()); ii <= c.x() + int(r.x()); ++ii) {
          if (!g.contains(ii, j, k) || liver.at(ii, j, k) != o.liver_label) continue;
          if ((g.index_to_lps_mm(Eigen::Vector3d(ii, j, k)) - V[i]).norm() <= reach_mm) {
            bed[i] = 1.0;
            break;
          }
        }
  }
  return bed;
}

/// Area of the part of triangle (a, b, c) where the linear interpolant of (fa, fb, fc) is ≥ 0.
double positive_area(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, double fa, double fb,
                     double fc) {
  const Eigen::Vector3d p[3] = {a, b, c};
  const double f[3] = {fa, fb, fc};
  std::vector<Eigen::Vector3d> poly;
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3;
    if (f[i] >= 0) poly.push_back(p[i]);
    if ((f[i] >= 0) != (f[j] >= 0)) poly.push_back(p[i] + (f[i] / (f[i] - f[j])) * (p[j] - p[i]));
  }
  double area = 0.0;
  for (std::size_t i = 1; i + 1 < poly.size(); ++i) area += 0.5 * (poly[i] - poly[0]).cross(poly[i + 1] - poly[0]).norm();
  return area;
}

}  // namespace

LiverBedScore liver_bed_score(const SurfaceMesh& gb, const LabelMap* liver, const DissectionOptions& o, const Volume* ct) {
  const auto& V = gb.vertices_lps_mm;
  LiverBedScore out;
  std::vector<double> score;
  std::string why_not;  // why the label or the CT could not give the bed
  if (liver && o.liver_label != 0 && liver->count(o.liver_label) > 0) {
    score = score_from_label(gb, *liver, o);
    if (std::find(score.begin(), score.end(), 1.0) != score.end()) out.source = "liver label";
    else {
      score.clear();
      why_not = "the liver label does not touch the gallbladder";
    }
  }
  if (score.empty() && ct && o.bed_from_ct) {
    out.ct_estimate = liver_bed_from_ct(gb, *ct, o.ct);
    const LiverBedEstimate& e = out.ct_estimate;
    if (e.reason.empty() && std::any_of(e.score.begin(), e.score.end(), [](double s) { return s >= 0.5; })) {
      score = e.score;
      out.source = "CT intensity";
    } else {
      if (!why_not.empty()) why_not += "; ";
      why_not += e.reason.empty() ? "no parenchyma of " + format_g(std::round(e.band_lo_hu)) + "–" +
                                                    format_g(std::round(e.band_hi_hu)) + " HU lies 3–5 mm outside the gallbladder"
                                  : e.reason;
    }
  }
  if (score.empty()) {
    out.source = "surface facing the liver direction" + (why_not.empty() ? "" : " (" + why_not + ")");
    const std::vector<Eigen::Vector3d> n = vertex_normals(gb);
    const Eigen::Vector3d dir = o.bed_direction_lps.normalized();
    const double c = std::cos(o.bed_angle_deg * std::numbers::pi / 180.0);
    score.assign(V.size(), 0.0);
    for (std::size_t i = 0; i < V.size(); ++i) score[i] = n[i].norm() > 0 && n[i].dot(dir) >= c ? 1.0 : 0.0;
  }

  // Smoothing over the surface: lazy neighbour averaging, n ≈ 2 (σ / mean edge)² steps.
  std::vector<std::vector<std::int32_t>> nb(V.size());
  double edge_sum = 0.0;
  std::size_t edge_count = 0;
  for (const auto& t : gb.triangles)
    for (int k = 0; k < 3; ++k) {
      const std::int32_t a = t[std::size_t(k)], b = t[std::size_t((k + 1) % 3)];
      nb[std::size_t(a)].push_back(b);
      nb[std::size_t(b)].push_back(a);
      edge_sum += (V[std::size_t(a)] - V[std::size_t(b)]).norm();
      ++edge_count;
    }
  for (auto& x : nb) {
    std::sort(x.begin(), x.end());
    x.erase(std::unique(x.begin(), x.end()), x.end());
  }
  const double mean_edge = edge_sum / double(std::max<std::size_t>(1, edge_count));
  const int steps = mean_edge > 0 ? std::min(500, int(std::lround(2.0 * std::pow(o.smoothing_mm / mean_edge, 2)))) : 0;
  std::vector<double> next(score.size());
  for (int s = 0; s < steps; ++s) {
    for (std::size_t i = 0; i < V.size(); ++i) {
      if (nb[i].empty()) { next[i] = score[i]; continue; }
      double m = 0.0;
      for (auto j : nb[i]) m += score[std::size_t(j)];
      next[i] = 0.5 * score[i] + 0.5 * m / double(nb[i].size());
    }
    std::swap(score, next);
  }
  out.vertex_score = std::move(score);
  return out;
}

namespace {

/// Total turning (degrees) and sharpest turn (degrees per mm) of a closed polyline.
std::pair<double, double> turning(const std::vector<Eigen::Vector3d>& p) {
  const std::size_t n = p.size();
  double total = 0, sharpest = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d u = p[i] - p[(i + n - 1) % n], v = p[(i + 1) % n] - p[i];
    if (u.norm() <= 0 || v.norm() <= 0) continue;
    const double angle = std::atan2(u.cross(v).norm(), u.dot(v)) * 180.0 / M_PI;
    total += angle;
    sharpest = std::max(sharpest, angle / (0.5 * (u.norm() + v.norm())));
  }
  return {total, sharpest};
}

/// A copy of `m` with its small-scale relief (facet creases, folds, slice terraces) smoothed away:
/// Taubin passes over the vertex neighbourhoods (λ = 0.5, μ = −0.53: no shrinkage).
SurfaceMesh smoothed_copy(const SurfaceMesh& m, int passes) {
  SurfaceMesh out = m;
  const std::size_t n = m.vertices_lps_mm.size();
  std::vector<std::vector<std::int32_t>> nb(n);
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      nb[std::size_t(t[std::size_t(k)])].push_back(t[std::size_t((k + 1) % 3)]);
      nb[std::size_t(t[std::size_t((k + 1) % 3)])].push_back(t[std::size_t(k)]);
    }
  for (auto& l : nb) {
    std::sort(l.begin(), l.end());
    l.erase(std::unique(l.begin(), l.end()), l.end());
  }
  auto& V = out.vertices_lps_mm;
  std::vector<Eigen::Vector3d> next(n);
  for (int it = 0; it < 2 * passes; ++it) {
    const double f = it % 2 == 0 ? 0.5 : -0.53;
    for (std::size_t i = 0; i < n; ++i) {
      if (nb[i].empty()) {
        next[i] = V[i];
        continue;
      }
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (auto j : nb[i]) c += V[std::size_t(j)];
      next[i] = V[i] + f * (c / double(nb[i].size()) - V[i]);
    }
    V.swap(next);
  }
  return out;
}

/// Nearest point of the closed polyline `q` to `x` (brute force: a rim has a few hundred points).
Eigen::Vector3d nearest_on_loop(const std::vector<Eigen::Vector3d>& q, const Eigen::Vector3d& x) {
  Eigen::Vector3d best = q[0];
  double best_d = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < q.size(); ++i) {
    const Eigen::Vector3d a = q[i], d = q[(i + 1) % q.size()] - a;
    const double t = d.squaredNorm() > 0 ? std::clamp((x - a).dot(d) / d.squaredNorm(), 0.0, 1.0) : 0.0;
    const Eigen::Vector3d c = a + t * d;
    if ((x - c).squaredNorm() < best_d) best_d = (x - c).squaredNorm(), best = c;
  }
  return best;
}

/// Curve-shortening on the surface: Laplacian passes over a closed polyline, each point then held
/// within o.surface_tolerance_mm of the surface, until no turn exceeds o.max_turn_deg_per_mm and
/// the total turning is within o.max_total_turning_deg (at most 400 passes). Shortening straightens the loop along the surface (its geodesic curvature
/// falls): it stops as soon as the sharpest turn is within the limit, so the loop keeps to the
/// rim (the drift is reported). Returns the passes taken.
std::size_t smooth_on_surface(std::vector<Eigen::Vector3d>& p, const SurfaceIndex& index, const DissectionOptions& o) {
  if (p.size() < 5) return 0;
  std::vector<Eigen::Vector3d> next;
  std::size_t passes = 0;
  // A loop cannot turn less sharply than a circle of its length (360° / length per mm): a small
  // bed's rim is held to twice that, not shortened away.
  auto limit = [&] {
    double length = 0;
    for (std::size_t i = 0; i < p.size(); ++i) length += (p[(i + 1) % p.size()] - p[i]).norm();
    return std::max(o.max_turn_deg_per_mm, 2 * 360.0 / std::max(length, 1e-9));
  };
  auto rough = [&] {
    const auto t = turning(p);
    return t.second > limit() || t.first > o.max_total_turning_deg;
  };
  while (passes < 400 && rough()) {
    if (passes % 10 == 0 && passes > 0) {  // shortening bunches the points: even them out
      Polyline loop;
      loop.closed = true;
      loop.points_lps_mm = p;
      p = resample_polyline(loop, o.spacing_mm).points_lps_mm;
    }
    const std::size_t n = p.size();
    next.resize(n);
    for (std::size_t i = 0; i < n; ++i) next[i] = 0.5 * p[i] + 0.25 * (p[(i + n - 1) % n] + p[(i + 1) % n]);
    for (std::size_t i = 0; i < n; ++i) {
      Eigen::Vector3d x = next[i];
      const auto c = index.closest(x);
      const double d = std::abs(c.signed_distance_mm);
      p[i] = d > o.surface_tolerance_mm ? c.point_lps_mm + (x - c.point_lps_mm) * (o.surface_tolerance_mm / d) : x;
    }
    ++passes;
  }
  return passes;
}

}  // namespace

DissectionPath gallbladder_dissection_path(const SurfaceMesh& gb, const LabelMap* liver, const DissectionOptions& o,
                                           const Volume* ct) {
  const auto& V = gb.vertices_lps_mm;
  if (gb.triangles.empty()) throw InputError(ExitCode::mesh_input, "the gallbladder surface has no triangle", {});
  DissectionPath out;
  LiverBedScore bed = liver_bed_score(gb, liver, o, ct);
  out.bed_source = std::move(bed.source);
  out.ct_estimate = std::move(bed.ct_estimate);
  const std::vector<double>& score = bed.vertex_score;
  out.vertex_score = score;
  // f ≥ 0 is the bed; no vertex exactly on the iso-value.
  std::vector<double> f(score.size());
  for (std::size_t i = 0; i < f.size(); ++i) f[i] = score[i] - 0.5 == 0.0 ? 1e-12 : score[i] - 0.5;
  double total_area = 0.0;
  for (const auto& t : gb.triangles) {
    const auto &a = V[std::size_t(t[0])], &b = V[std::size_t(t[1])], &c = V[std::size_t(t[2])];
    total_area += 0.5 * (b - a).cross(c - a).norm();
    out.bed_area_mm2 += positive_area(a, b, c, f[std::size_t(t[0])], f[std::size_t(t[1])], f[std::size_t(t[2])]);
  }
  out.covered_fraction = total_area > 0 ? out.bed_area_mm2 / total_area : 0.0;
  const bool any_bed = std::any_of(f.begin(), f.end(), [](double x) { return x > 0; });
  const bool all_bed = std::all_of(f.begin(), f.end(), [](double x) { return x > 0; });
  if (!any_bed || all_bed)
    throw InputError(ExitCode::mesh_input,
                     !any_bed ? "no part of the gallbladder surface lies in the liver bed (" + out.bed_source + ")"
                              : "the liver bed covers the whole gallbladder surface: no rim to dissect along (" +
                                    out.bed_source + ")",
                     {}, "check the liver label or the bed options of the guide stage");

  // The 0.5 iso-line: a point on each edge whose ends straddle it, two per straddling triangle.
  std::map<std::pair<std::int32_t, std::int32_t>, std::int32_t> point_of_edge;
  std::vector<Eigen::Vector3d> pts;
  std::vector<std::array<std::int32_t, 2>> link;
  auto edge_point = [&](std::int32_t a, std::int32_t b) {
    const auto key = std::minmax(a, b);
    auto [it, fresh] = point_of_edge.emplace(key, std::int32_t(pts.size()));
    if (fresh) {
      const double fa = f[std::size_t(key.first)], fb = f[std::size_t(key.second)];
      pts.push_back(V[std::size_t(key.first)] + (fa / (fa - fb)) * (V[std::size_t(key.second)] - V[std::size_t(key.first)]));
      link.push_back({-1, -1});
    }
    return it->second;
  };
  auto connect = [&](std::int32_t p, std::int32_t q) {
    for (auto [x, y] : {std::pair{p, q}, std::pair{q, p}}) {
      auto& l = link[std::size_t(x)];
      if (l[0] < 0) l[0] = y;
      else if (l[1] < 0) l[1] = y;
      // a third link would mean a non-manifold edge: that part of the iso-line is dropped below
      else l = {-2, -2};
    }
  };
  for (const auto& t : gb.triangles) {
    std::int32_t ends[2];
    int n = 0;
    for (int k = 0; k < 3; ++k) {
      const std::int32_t a = t[std::size_t(k)], b = t[std::size_t((k + 1) % 3)];
      if ((f[std::size_t(a)] > 0) != (f[std::size_t(b)] > 0) && n < 2) ends[n++] = edge_point(a, b);
    }
    if (n == 2) connect(ends[0], ends[1]);
  }
  std::vector<std::vector<std::int32_t>> loops;
  std::vector<char> used(pts.size(), 0);
  for (std::int32_t s = 0; s < std::int32_t(pts.size()); ++s) {
    if (used[std::size_t(s)] || link[std::size_t(s)][0] < 0 || link[std::size_t(s)][1] < 0) continue;
    std::vector<std::int32_t> loop{s};
    used[std::size_t(s)] = 1;
    std::int32_t prev = s, cur = link[std::size_t(s)][0];
    bool closed = false;
    while (cur >= 0 && !used[std::size_t(cur)]) {
      used[std::size_t(cur)] = 1;
      loop.push_back(cur);
      const auto& l = link[std::size_t(cur)];
      if (l[0] < 0 || l[1] < 0) break;
      const std::int32_t nxt = l[0] == prev ? l[1] : l[0];
      prev = cur;
      cur = nxt;
    }
    closed = cur == s;
    if (closed && loop.size() >= 3) loops.push_back(std::move(loop));
  }
  out.rim_loops = loops.size();
  if (loops.empty()) throw InputError(ExitCode::mesh_input, "the liver bed has no closed rim on the gallbladder surface", {});
  auto loop_length = [&](const std::vector<std::int32_t>& l) {
    double s = 0;
    for (std::size_t i = 0; i < l.size(); ++i) s += (pts[std::size_t(l[(i + 1) % l.size()])] - pts[std::size_t(l[i])]).norm();
    return s;
  };
  auto longest = *std::max_element(loops.begin(), loops.end(),
                                   [&](const auto& a, const auto& b) { return loop_length(a) < loop_length(b); });
  // Start at the most cranial point, so that the path reads the same way on every run.
  std::rotate(longest.begin(),
              std::max_element(longest.begin(), longest.end(),
                               [&](std::int32_t a, std::int32_t b) { return pts[std::size_t(a)].z() < pts[std::size_t(b)].z(); }),
              longest.end());
  Polyline rim;
  rim.name = "gallbladder_dissection";
  rim.closed = true;
  for (auto i : longest) rim.points_lps_mm.push_back(pts[std::size_t(i)]);
  rim = smooth_polyline(resample_polyline(rim, 0.25), o.smoothing_mm);
  rim = resample_polyline(rim, o.spacing_mm);
  const SurfaceIndex index({gb});
  for (auto& q : rim.points_lps_mm) q = index.closest(q).point_lps_mm;
  // Snapped onto facets, the rim turns wherever it crosses an edge between two of them (and
  // wherever the bed score steps between slices): a curve a hand follows is smoothed along the
  // surface instead, within a tolerance of it, until its sharpest turn is below the limit.
  const std::vector<Eigen::Vector3d> snapped = rim.points_lps_mm;
  out.smoothing_passes = smooth_on_surface(rim.points_lps_mm, SurfaceIndex({smoothed_copy(gb, 30)}), o);
  for (const auto& q : rim.points_lps_mm) {
    const double d = (q - nearest_on_loop(snapped, q)).norm();
    out.max_drift_mm = std::max(out.max_drift_mm, d);
    out.mean_drift_mm += d / double(rim.points_lps_mm.size());
  }
  {
    const auto [total, sharpest] = turning(rim.points_lps_mm);
    out.total_turning_deg = total;
    out.max_turn_deg_per_mm = sharpest;
  }
  const auto& l = rim.points_lps_mm;
  const std::size_t m = l.size();
  for (std::size_t i = 0; i < m; ++i) {
    out.max_surface_distance_mm = std::max(out.max_surface_distance_mm, std::abs(index.closest(l[i]).signed_distance_mm));
    out.max_surface_distance_mm =
        std::max(out.max_surface_distance_mm, std::abs(index.closest(0.5 * (l[i] + l[(i + 1) % m])).signed_distance_mm));
  }
  // Simplicity: segments more than 3 mm apart along the loop must not meet.
  std::vector<double> arc(m + 1, 0.0);
  for (std::size_t i = 0; i < m; ++i) arc[i + 1] = arc[i] + (l[(i + 1) % m] - l[i]).norm();
  out.length_mm = arc[m];
  out.min_self_distance_mm = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < m; ++i)
    for (std::size_t j = i + 1; j < m; ++j) {
      const double along = std::min(arc[j] - arc[i], out.length_mm - (arc[j] - arc[i]));
      if (along <= 3.0 + 2.0 * o.spacing_mm) continue;
      out.min_self_distance_mm =
          std::min(out.min_self_distance_mm, segment_distance(l[i], l[(i + 1) % m], l[j], l[(j + 1) % m]));
    }
  if (!std::isfinite(out.min_self_distance_mm)) out.min_self_distance_mm = 0.0;
  out.line = std::move(rim);
  return out;
}

}  // namespace organsmith::physics
