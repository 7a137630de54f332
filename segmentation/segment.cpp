// Over 400 lines: the segmentation stage: the seeded and the airway drivers, slice-to-slice
// propagation and label assembly share one per-slice context.
#include "segmentation/segment.h"

#include "segmentation/edge_map.h"
#include "segmentation/gvf.h"
#include "segmentation/presets.h"
#include "segmentation/detail/region3d.h"
#include "segmentation/detail/section_rules.h"
#include "segmentation/slice_ops.h"
#include "segmentation/snake.h"
#include "segmentation/surface3d.h"

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <numeric>
#include <optional>

namespace organsmith {

using seg::Image2f;
using seg::Point2;
using seg::area_outside;
using seg::part_within;

namespace {

/// A second pass with the window recentred on the organ's median replaces the first only if it
/// keeps at least this fraction of the first pass's volume. 0.5 let a pass that lost the organ's
/// lower half to one short section win; 0.8 changes none of the shared sweep's runs and lifts 63
/// noisier thick-slice runs from mean Dice 0.826 to 0.833 (segmentation README); 0.95 drops the
/// shared real sweep's lowest run from 0.868 to 0.846.
constexpr double kMinRecentredVolumeFraction = 0.8;

std::string fmt_mm(const Eigen::Vector3d& p) {
  char b[96];
  std::snprintf(b, sizeof b, "(%.1f, %.1f, %.1f) mm LPS", p.x(), p.y(), p.z());
  return b;
}

struct Roi {
  int x0 = 0, y0 = 0, w = 0, h = 0;
};

/// Everything the per-slice fit needs about the volume.
struct SliceCtx {
  const Volume& vol;
  int W, H;
  double sx, sy;
  explicit SliceCtx(const Volume& v)
      : vol(v), W(int(v.grid.size_vox[0])), H(int(v.grid.size_vox[1])), sx(v.grid.spacing_mm.x()),
        sy(v.grid.spacing_mm.y()) {}
};

Roi roi_around(const SliceCtx& c, const std::vector<Point2>& pts, double margin_mm) {
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (const auto& p : pts) {
    xmin = std::min(xmin, p.x), xmax = std::max(xmax, p.x);
    ymin = std::min(ymin, p.y), ymax = std::max(ymax, p.y);
  }
  Roi r;
  r.x0 = std::clamp(int(std::floor((xmin - margin_mm) / c.sx)), 0, c.W - 1);
  r.y0 = std::clamp(int(std::floor((ymin - margin_mm) / c.sy)), 0, c.H - 1);
  const int x1 = std::clamp(int(std::ceil((xmax + margin_mm) / c.sx)), 0, c.W - 1);
  const int y1 = std::clamp(int(std::ceil((ymax + margin_mm) / c.sy)), 0, c.H - 1);
  r.w = x1 - r.x0 + 1;
  r.h = y1 - r.y0 + 1;
  return r;
}

std::vector<float> crop(const SliceCtx& c, std::int64_t k, const Roi& r) {
  std::vector<float> out(std::size_t(r.w) * r.h);
  const float* s = c.vol.slice(k);
  for (int y = 0; y < r.h; ++y)
    std::copy_n(s + std::size_t(r.y0 + y) * c.W + r.x0, r.w, out.data() + std::size_t(y) * r.w);
  return out;
}

std::vector<Point2> to_px(const SliceCtx& c, const std::vector<Point2>& mm, double ox = 0, double oy = 0) {
  std::vector<Point2> px;
  px.reserve(mm.size());
  for (const auto& p : mm) px.push_back({p.x / c.sx - ox, p.y / c.sy - oy});
  return px;
}

/// Median of the HU values of slice k inside a polygon (slice mm); NaN when it covers no pixel.
double median_inside(const SliceCtx& c, std::int64_t k, const std::vector<Point2>& mm) {
  std::vector<float> v;
  const float* s = c.vol.slice(k);
  seg::rasterise(to_px(c, mm), c.W, c.H, [&](int x, int y) { v.push_back(s[std::size_t(y) * c.W + x]); });
  if (v.empty()) return std::nan("");
  auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

Point2 centroid(const std::vector<Point2>& p) {
  // Area centroid of the polygon (falls back to the vertex mean for degenerate ones).
  double a = 0, cx = 0, cy = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Point2& q = p[i];
    const Point2& r = p[(i + 1) % p.size()];
    const double c = q.x * r.y - r.x * q.y;
    a += c;
    cx += (q.x + r.x) * c;
    cy += (q.y + r.y) * c;
  }
  if (std::abs(a) < 1e-9) {
    Point2 m;
    for (const auto& q : p) m.x += q.x / p.size(), m.y += q.y / p.size();
    return m;
  }
  return {cx / (3 * a), cy / (3 * a)};
}

std::vector<Point2> scaled(const std::vector<Point2>& p, double f) {
  const Point2 c = centroid(p);
  std::vector<Point2> out;
  for (const auto& q : p) out.push_back({c.x + f * (q.x - c.x), c.y + f * (q.y - c.y)});
  return out;
}

/// The region test's smoothing (mm): at least region_sigma_px pixels, since the per-voxel noise
/// the region test must average out is set by the voxel, while smoothing in mm moves the boundary.
double region_sigma_mm(const OrganPreset& p, const SliceCtx& c) {
  return std::max(p.region_sigma_mm, p.region_sigma_px * std::min(c.sx, c.sy));
}

struct Fit {
  std::vector<Point2> pts;  // slice mm
  double area_mm2 = 0;
  double edge_support = 1;  // fraction of the contour with a visible wall outside it (seating)
  bool touches_roi = false;
};

/// Where a section may lie: within margin_mm of the polygon `around` (slice mm).
struct Reach {
  std::vector<Point2> around;
  double margin_mm = 0;
};

/// Fraction of a contour's points (slice mm) held at the reach's limit: outside `around` and at
/// least margin_mm − tol_mm from it. A section that continues the organ rests on its wall; one
/// that fills the reach (past the organ's end) rests on the limit.
double pinned_fraction(const std::vector<Point2>& pts, const Reach& reach, double tol_mm) {
  if (pts.empty() || reach.around.size() < 3) return 0.0;
  std::size_t pinned = 0;
  for (const auto& q : pts)
    if (!seg::point_in_polygon(reach.around, q) && seg::distance_to_boundary(reach.around, q) >= reach.margin_mm - tol_mm)
      ++pinned;
  return double(pinned) / double(pts.size());
}

/// Runs the GVF snake of `p` on slice k from `init` (slice mm), with the region pressure
/// positive for smoothed HU in [lo, hi] (and, given `reach`, only within it).
Fit fit_slice(const SliceCtx& c, std::int64_t k, const std::vector<Point2>& init, const OrganPreset& p, double lo,
              double hi, double margin_mm, double open_mm, const Reach* reach = nullptr) {
  Fit fit;
  for (int attempt = 0; attempt < 3; ++attempt) {
    const Roi r = roi_around(c, init, margin_mm);
    const std::vector<float> hu = crop(c, k, r);
    const Image2f f = seg::edge_map(hu.data(), r.w, r.h, c.sx, c.sy,
                                    {p.edge_window_lo_hu, p.edge_window_hi_hu, p.edge_sigma_mm});
    seg::GvfMultigridOptions go;
    go.mu = p.gvf_mu;
    go.tolerance = 1e-3;  // the snake needs the field's direction, not six digits
    seg::GvfField g = seg::gvf_multigrid(f, go);
    // Saturate the field: unit magnitude wherever it is at least 15 % of its maximum, so a weak
    // edge (bile against liver) pulls as firmly as a strong one (fat against muscle).
    float mmax = 0;
    for (std::size_t i = 0; i < g.u.px.size(); ++i) mmax = std::max(mmax, std::hypot(g.u.px[i], g.v.px[i]));
    const float floor_m = std::max(0.15f * mmax, 1e-12f);
    for (std::size_t i = 0; i < g.u.px.size(); ++i) {
      const float s = 1.0f / std::max(std::hypot(g.u.px[i], g.v.px[i]), floor_m);
      g.u.px[i] *= s;
      g.v.px[i] *= s;
    }
    const double region_sigma = region_sigma_mm(p, c);
    Image2f pr = seg::smooth_slice(hu.data(), r.w, r.h, c.sx, c.sy, region_sigma);
    const float ramp = float(p.pressure_ramp_hu);
    for (float& v : pr.px) v = std::clamp(std::min(v - float(lo), float(hi) - v) / ramp, -1.0f, 1.0f);
    if (open_mm > 0) {
      // Grey-level opening removes ridges of "organ-like" pressure thinner than the kernel: the
      // partial-volume band where two other tissues meet (liver 60 HU against fat −100 HU
      // passes through bile's 0–20 HU) would otherwise lead the snake out along the interface.
      const int rx = std::max(1, int(std::lround(open_mm / c.sx)));
      const int ry = std::max(1, int(std::lround(open_mm / c.sy)));
      cv::Mat m(r.h, r.w, CV_32F, pr.px.data());
      cv::morphologyEx(m, m, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * rx + 1, 2 * ry + 1}),
                       {-1, -1}, 1, cv::BORDER_REPLICATE);
    }
    if (p.edge_stop > 0) {
      // Balloon with an edge stop (Cohen 1991; Caselles et al. 1997): the pressure fades where the
      // edge map is strong, so a weak wall between the organ and a neighbour of similar HU
      // (gallbladder against duodenum) holds the contour and the GVF force seats it there.
      const float inv = float(1.0 / p.edge_stop);
      for (std::size_t i = 0; i < pr.px.size(); ++i)
        if (pr.px[i] > 0) pr.px[i] /= 1.0f + f.px[i] * inv;
    }
    if (reach && reach->around.size() >= 3) {
      // Beyond the reach the pressure pulls inwards.
      cv::Mat allowed = cv::Mat::zeros(r.h, r.w, CV_8U);
      seg::rasterise(to_px(c, reach->around, r.x0, r.y0), r.w, r.h,
                     [&](int x, int y) { allowed.at<std::uint8_t>(y, x) = 255; });
      const int rx = int(std::lround(reach->margin_mm / c.sx)), ry = int(std::lround(reach->margin_mm / c.sy));
      if (rx > 0 || ry > 0)
        cv::dilate(allowed, allowed, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * rx + 1, 2 * ry + 1}));
      for (int y = 0; y < r.h; ++y)
        for (int x = 0; x < r.w; ++x)
          if (!allowed.at<std::uint8_t>(y, x)) pr(x, y) = -1.0f;
    }
    seg::SnakeForces forces{&g.u, &g.v, &pr, c.sx, c.sy};
    seg::SnakeOptions so;
    so.alpha = p.alpha;
    so.beta = p.beta;
    so.kappa = p.kappa;
    so.balloon = p.balloon;
    so.point_spacing_mm = p.point_spacing_mm;
    so.max_iterations = p.max_iterations;
    const double ox = r.x0 * c.sx, oy = r.y0 * c.sy;
    std::vector<Point2> local;
    for (const auto& q : init) local.push_back({q.x - ox, q.y - oy});
    seg::SnakeResult s = seg::evolve_snake(local, forces, so);
    if (p.neck_ratio > 0) {
      seg::NeckOptions no;
      no.max_neck_ratio = p.neck_ratio;
      no.min_depth_mm = p.neck_depth_mm;
      s.points = seg::cut_necks(s.points, local, no);
    }
    if (p.seat_band_mm > 0 && s.points.size() >= 8) {
      // Seating: the region window that found the organ is deliberately conservative (it stops
      // short of the half-way HU so that it does not leak), so the contour rests a fraction of
      // the blur width inside the wall — further the brighter the neighbour (contrast-enhanced
      // liver). Each point moves along its normal, by at most seat_band_mm, to where the smoothed
      // HU steps half-way between the organ's mean and the tissue just outside — the boundary of a
      // blurred wall, and the convention of voxel-centre labels. Where the outside does not
      // differ from the organ by seat_min_contrast_hu (no visible wall), the point stays.
      const Image2f sm = seg::smooth_slice(hu.data(), r.w, r.h, c.sx, c.sy, p.seat_sigma_mm);
      const auto& P = s.points;
      const std::size_t n = P.size();
      // The organ's mean: the window is [mean − region_below_hu, mean + region_above_hu].
      const double organ = lo + p.region_below_hu, step = 0.1, reach = p.seat_band_mm + p.seat_outside_mm;
      std::vector<double> shift(n, 0.0), nx(n), ny(n);
      std::size_t walled = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const Point2& a = P[(i + n - 1) % n];
        const Point2& b = P[(i + 1) % n];
        const double tl = std::hypot(b.x - a.x, b.y - a.y);
        nx[i] = tl > 0 ? (b.y - a.y) / tl : 0;  // outward normal of a counter-clockwise contour
        ny[i] = tl > 0 ? -(b.x - a.x) / tl : 0;
        auto at = [&](double t) { return double(sm.sample((P[i].x + t * nx[i]) / c.sx, (P[i].y + t * ny[i]) / c.sy)); };
        const double out = at(reach);
        if (std::abs(out - organ) < p.seat_min_contrast_hu) continue;
        ++walled;
        // Where the profile steps from the organ to the outside: the split of the band into an
        // organ part and an outside part with the least squared misfit to the two levels. Each
        // sample moved across the split changes that misfit by (out − organ)(2v − organ − out), so
        // the split is where the running sum of that term is lowest — the half-way crossing of a
        // blurred wall, taken over the whole band rather than at the nearest (noise) crossing.
        double run = 0, lowest = 0, best = -p.seat_band_mm;
        for (double t = -p.seat_band_mm; t <= p.seat_band_mm + 1e-9; t += step) {
          run += (out - organ) * (2.0 * at(t) - organ - out);
          if (run < lowest) lowest = run, best = t + step;
        }
        shift[i] = std::min(best, p.seat_band_mm);
      }
      // Smooth the shifts along the contour (a wall is not seated point by point through noise).
      std::vector<Point2> moved(n);
      for (std::size_t i = 0; i < n; ++i) {
        double sum = 0;
        for (std::size_t j = 0; j < 5; ++j) sum += shift[(i + n - 2 + j) % n];
        const double t = sum / 5.0;
        moved[i] = {P[i].x + t * nx[i], P[i].y + t * ny[i]};
      }
      fit.edge_support = double(walled) / double(n);
      seg::remove_loops(moved);
      if (moved.size() >= 8) s.points = std::move(moved);
    }
    fit.pts.clear();
    for (const auto& q : s.points) fit.pts.push_back({q.x + ox, q.y + oy});
    fit.area_mm2 = std::abs(seg::polygon_area(fit.pts));
    // A contour that reached the working window's edge (not the image's) may have been stopped
    // by the crop: retry with a wider window.
    fit.touches_roi = false;
    for (const auto& q : s.points) {
      const double px = q.x / c.sx, py = q.y / c.sy;
      if ((px < 1.0 && r.x0 > 0) || (py < 1.0 && r.y0 > 0) || (px > r.w - 2.0 && r.x0 + r.w < c.W) ||
          (py > r.h - 2.0 && r.y0 + r.h < c.H))
        fit.touches_roi = true;
    }
    if (!fit.touches_roi) break;
    margin_mm *= 2;
  }
  return fit;
}

/// The preset adapted to the image's noise, a named step of the seeded driver (`noise_hu`: the
/// noise measured around the seed, slice_noise_hu).
void adapt_to_noise(OrganPreset& p, const SliceCtx& c, double noise_hu) {
  // Smoothing before the region test grows with the image's noise (a Gaussian of σ pixels leaves
  // noise / (2√π σ) of white noise) until what is left is below region_noise_hu, so that the
  // pressure's sign is the tissue's and not the noise's, at any pixel size and dose.
  if (p.region_noise_hu > 0 && noise_hu > 0)
    p.region_sigma_px = std::max(p.region_sigma_px,
                                 std::min(noise_hu / (2.0 * std::sqrt(M_PI) * p.region_noise_hu),
                                          p.region_noise_max_sigma_mm / std::min(c.sx, c.sy)));
  // Where that smoothing is capped (coarse pixels, a noisy scan) noise is left; the window must
  // then be wider than it, or the organ's own pixels fall outside by noise alone and the balloon
  // turns inwards. At 2.33 σ of what is left, one inside pixel in a hundred does (one-sided).
  if (noise_hu > 0) {
    const double sigma_px = region_sigma_mm(p, c) / std::min(c.sx, c.sy);
    const double left_hu = noise_hu / (2.0 * std::sqrt(M_PI) * std::max(sigma_px, 0.5));
    p.region_above_hu = std::max(p.region_above_hu, 2.33 * left_hu);
    p.region_below_hu = std::max(p.region_below_hu, 2.33 * left_hu);
  }
}

/// The opening radius for a section of `area_mm2`: a fraction of the organ's equivalent radius
/// (at least region_open_mm), so that necks through which the snake could leak into a
/// neighbour of similar HU (duodenum, bowel) are cut at any voxel size while the organ survives.
double opening_for(const OrganPreset& p, double area_mm2) {
  return std::max(p.region_open_mm, p.region_open_fraction * std::sqrt(area_mm2 / M_PI));
}

/// The start section, a named step of seeded propagation: the snake from a small circle at the
/// seed `s` on slice k0 in the window [mu − region_below_hu, mu + region_above_hu]; with `refine`,
/// fitted once more with the window centred on the section's own median (the organ's mean is
/// better estimated over its cross-section than around the seed) where that median is seed-like
/// and 2 HU or more away; then opened for its own size (opening_for) until its area settles
/// (two passes at most; an opening that removes the organ keeps the last fit). Returns the section
/// and the window it was fitted in.
struct StartSection {
  Fit fit;
  double mu = 0, lo = 0, hi = 0;
};
StartSection start_section(const SliceCtx& c, std::int64_t k0, Point2 s, const OrganPreset& p, double mu, bool refine,
                           double seed_margin_mm) {
  StartSection st;
  auto fit_at = [&](double open_mm) {
    return fit_slice(c, k0, seg::circle(s, p.start_radius_mm, 16), p, st.lo, st.hi, seed_margin_mm, open_mm);
  };
  st.mu = mu, st.lo = mu - p.region_below_hu, st.hi = mu + p.region_above_hu;
  Fit f0 = fit_at(p.region_open_mm);
  if (f0.area_mm2 >= p.min_area_mm2) {
    const double m2 = median_inside(c, k0, f0.pts);
    if (refine && m2 >= p.seed_hu_lo && m2 <= p.seed_hu_hi && std::abs(m2 - mu) > 2.0) {
      st.mu = m2, st.lo = m2 - p.region_below_hu, st.hi = m2 + p.region_above_hu;
      f0 = fit_at(p.region_open_mm);
    }
  }
  for (int pass = 0; pass < 2 && f0.area_mm2 >= p.min_area_mm2; ++pass) {
    Fit f1 = fit_at(opening_for(p, f0.area_mm2));
    if (f1.area_mm2 < p.min_area_mm2) break;
    const bool same = std::abs(f1.area_mm2 - f0.area_mm2) < 0.02 * f0.area_mm2;
    f0 = std::move(f1);
    if (same) break;
  }
  st.fit = std::move(f0);
  return st;
}

/// The continuity hold, a named step of seeded propagation: a slice whose section leaked (a wall
/// that noise or partial volume hides, the duodenum beside the organ on a thick slice) is fitted
/// again with the pressure held within continuity_margin_mm + continuity_slope × the slice
/// spacing of the previous section, moved by the organ's drift (`moved_previous`). The held
/// section is offered only where it rests on the organ's wall rather than on the reach's limit:
/// at most max_pinned_fraction of it on the limit, or max_pinned_fraction_walled where its wall
/// is seen around min_walled_edge_support of it (segmentation README, "Held sections with their
/// wall"). Nothing when it rests on the limit; the caller still tests it like any section.
std::optional<Fit> continuity_hold(const SliceCtx& c, std::int64_t k, const std::vector<Point2>& moved_previous,
                                   const OrganPreset& p, double lo, double hi, double open_mm, double slice_mm) {
  Reach reach;
  reach.around = moved_previous;
  reach.margin_mm = p.continuity_margin_mm + p.continuity_slope * slice_mm;
  Fit held = fit_slice(c, k, scaled(reach.around, 0.7), p, lo, hi, p.roi_margin_mm, open_mm, &reach);
  const double pinned = pinned_fraction(held.pts, reach, std::max(c.sx, c.sy));
  const bool rests_on_wall = pinned <= p.max_pinned_fraction ||
                             (pinned <= p.max_pinned_fraction_walled && held.edge_support >= p.min_walled_edge_support);
  if (!rests_on_wall) return std::nullopt;
  return held;
}

seg::Point2 to_slice_mm(const SliceCtx& c, const Eigen::Vector3d& ijk) { return {ijk.x() * c.sx, ijk.y() * c.sy}; }

Contour to_contour(const Volume& v, std::int64_t k, const std::vector<Point2>& pts) {
  Contour ct;
  ct.slice_k = k;
  ct.closed = true;
  const double sx = v.grid.spacing_mm.x(), sy = v.grid.spacing_mm.y();
  for (const auto& q : pts) ct.points_lps_mm.push_back(v.grid.index_to_lps_mm({q.x / sx, q.y / sy, double(k)}));
  return ct;
}

// ---------------------------------------------------------------------------------------------
// Gallbladder (and any seeded organ): a snake from a small circle at the seed, then slice to
// slice in both directions, each slice started from its neighbour's converged contour.

struct SliceContour {
  std::int64_t k;
  std::vector<Point2> pts;
};

/// The median HU over every section found (the pixels inside the contours): the centre of the
/// recentred window; nothing when the sections hold no pixel.
std::optional<double> sections_median_hu(const Volume& vol, const SliceCtx& c, const std::vector<SliceContour>& sections) {
  std::vector<float> v;
  for (const auto& sc : sections) {
    const float* sl = vol.slice(sc.k);
    seg::rasterise(to_px(c, sc.pts), c.W, c.H, [&](int x, int y) { v.push_back(sl[std::size_t(y) * c.W + x]); });
  }
  if (v.empty()) return std::nullopt;
  auto mid = v.begin() + std::ptrdiff_t(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return double(*mid);
}

/// Noise of slice k in a square of half-side `half_mm` around `centre` (slice mm): the robust
/// (median absolute) spread of differences between horizontal neighbours in soft tissue, ÷ √2.
/// Anatomy adds little: most neighbour pairs lie inside one tissue.
double slice_noise_hu(const SliceCtx& c, std::int64_t k, Point2 centre, double half_mm) {
  const int x0 = std::max(0, int((centre.x - half_mm) / c.sx)), x1 = std::min(c.W - 2, int((centre.x + half_mm) / c.sx));
  const int y0 = std::max(0, int((centre.y - half_mm) / c.sy)), y1 = std::min(c.H - 1, int((centre.y + half_mm) / c.sy));
  const float* s = c.vol.slice(k);
  std::vector<float> d;
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const float a = s[std::size_t(y) * c.W + x], b = s[std::size_t(y) * c.W + x + 1];
      if (std::abs(a) < 200 && std::abs(b) < 200) d.push_back(std::abs(a - b));
    }
  if (d.size() < 16) return 0;
  auto mid = d.begin() + std::ptrdiff_t(d.size() / 2);
  std::nth_element(d.begin(), mid, d.end());
  return 1.4826 * double(*mid) / std::sqrt(2.0);
}

/// One propagation attempt's outcome: every section found (the start's among them) in slice order.
struct Attempt {
  std::vector<SliceContour> all;
  std::string note_up, note_down;
  std::vector<std::int64_t> held;  // slices fitted again within the previous section's reach
  double lo = 0, hi = 0, mu = 0;
};

/// Count and time of the attempts of one kind (at the seed, slid off its slice, for a longer organ,
/// recentred windows): each re-runs the whole two-direction propagation, so their cost is reported.
struct AttemptCost {
  int count = 0;
  double seconds = 0;
};

/// A seeded organ's fixed inputs (image, preset, seed) and its attempts: each attempt fits the
/// start section on slice k0 with the window centred on mu, then propagates both ways; the retries
/// in segment_seeded change k0 or mu and attempt again.
struct SeededRun {
  const Volume& vol;
  const SliceCtx& c;
  const OrganPreset& p;
  Eigen::Vector3d ijk;        ///< the seed, index
  Eigen::Vector3d seed_lps;   ///< the seed, LPS mm
  Point2 s;                   ///< the seed on its slice, mm
  double seed_margin = 0;     ///< working window of the start section, mm
  bool parallel = true;
  Progress& progress;
  std::int64_t k0 = 0;        ///< the next attempt's start slice
  std::string kind = "at the seed";  ///< the next attempt's kind (its cost's key)
  std::map<std::string, AttemptCost> costs;
  std::atomic<int> done{0};

  /// The start of an attempt: its section, window and the organ's coarse 3-D region.
  struct Start {
    Fit f0;
    double lo = 0, hi = 0, mu = 0;
    std::int64_t k0 = 0;
    seg::Region3d region;
  };
  /// One direction's sections, why it stopped, and the slices held within reach.
  struct Direction {
    std::vector<SliceContour> acc;
    std::string note;
    std::vector<std::int64_t> held;
  };

  /// The median HU around the seed's position on slice k (the organ's window is centred on it).
  double hu_at_seed(std::int64_t k) const {
    return median_inside(c, k, seg::circle(s, std::max(p.seed_radius_mm, c.sx), 24));
  }
  /// Whether a median lies in the organ's seed range.
  bool seed_like(double m) const { return m >= p.seed_hu_lo && m <= p.seed_hu_hi; }

  /// Retry 1, the slide: a seed in a section too small to fit (a neck or a fundus tip a few pixels
  /// across, blurred with the liver around it) starts from the nearest slice within
  /// seed_slide_mm where the section at the seed's position fits; propagation then comes back
  /// through the seed's slice. Throws the seed slice's own failure where none fits.
  Attempt at_or_near_seed(std::int64_t k_seed, double seed_med) {
    const std::int64_t K = vol.grid.size_vox[2];
    const int slide = int(std::floor(p.seed_slide_mm / vol.grid.spacing_mm.z() + 1e-9));
    for (int d = 0;; ++d) {
      for (int sign : {-1, 1}) {
        if (d == 0 && sign > 0) continue;
        k0 = k_seed + sign * d;
        if (k0 < 0 || k0 >= K) continue;
        const double m = d == 0 ? seed_med : hu_at_seed(k0);
        if (!seed_like(m)) continue;
        kind = d == 0 ? "at the seed" : "slid off the seed's slice";
        try {
          return attempt(m, true);
        } catch (const SegmentationError& e) {
          if (e.code() != ExitCode::organ_not_found || d >= slide) throw;
        }
      }
      if (d >= slide) {
        k0 = k_seed;
        kind = "at the seed";
        return attempt(seed_med, true);  // reports why the seed's own slice fails
      }
    }
  }

  /// Retry 2, a longer organ: a seed at the organ's tip can start on a neighbour touching it there
  /// (a bowel loop beside the fundus on a noisy scan: the seed's section fitted the bowel with 13 of
  /// its 75 pixels on the organ, and both directions followed the bowel for one slice). An organ
  /// shorter than min_extent_mm along the slices is not one: the starts on the slices within
  /// seed_slide_mm are tried too, and the longest result is kept. Says why where it moved the start.
  std::optional<std::string> for_a_longer_organ(Attempt& at, std::int64_t k_seed) {
    const ImageGrid& g = vol.grid;
    const std::int64_t K = g.size_vox[2];
    const int slide = int(std::floor(p.seed_slide_mm / g.spacing_mm.z() + 1e-9));
    auto extent_mm = [&](const Attempt& a) { return double(a.all.back().k - a.all.front().k + 1) * g.spacing_mm.z(); };
    if (extent_mm(at) >= p.min_extent_mm) return std::nullopt;
    const double first_mm = extent_mm(at);
    const std::int64_t k_first = k0;
    std::int64_t k_best = k0;
    for (int d = 1; d <= std::max(1, slide); ++d)
      for (int sign : {-1, 1}) {
        k0 = k_seed + sign * d;
        if (k0 < 0 || k0 >= K) continue;
        const double m = hu_at_seed(k0);
        if (!seed_like(m)) continue;
        kind = "for a longer organ";
        try {
          Attempt other = attempt(m, true);
          if (extent_mm(other) > extent_mm(at)) at = std::move(other), k_best = k0;
        } catch (const SegmentationError&) {
          // no organ from this start
        }
      }
    k0 = k_best;
    if (k0 == k_first) return std::nullopt;
    char b[160];
    std::snprintf(b, sizeof b, "the start at the seed gave an organ %.0f mm long across the slices (under %.0f mm)",
                  first_mm, p.min_extent_mm);
    return std::string(b);
  }

  /// Retry 3, the recentred window: the organ's median over every slice found is a steadier centre
  /// for the window than one slice around the seed (seeds a slice apart gave windows 6 HU apart on
  /// a real scan); a second pass with it makes the result depend less on where the seed was
  /// placed. The median of a pass depends on its window (a lower window leaves out the brighter
  /// rim), so this repeats until the centre moves by at most 1.5 HU (three passes at most).
  void recentre(Attempt& at) {
    for (int pass = 0; pass < 3; ++pass) {
      bool moved = false;
      if (const std::optional<double> median = sections_median_hu(vol, c, at.all)) {
        const double m3 = *median;
        if (seed_like(m3) && std::abs(m3 - at.mu) > 1.5) {
          kind = "recentred window";
          try {
            Attempt second = attempt(m3, false);
            // A window a few HU away changes the outline a little; a second pass that loses a
            // fifth of the organ or more (a section in the organ's middle fitted short on a noisy
            // slice, after which propagation ended at the jump back) is not the steadier one.
            auto volume = [](const Attempt& a) {
              double v = 0;
              for (const auto& sc : a.all) v += std::abs(polygon_area(sc.pts));
              return v;
            };
            if (volume(second) >= kMinRecentredVolumeFraction * volume(at)) at = std::move(second), moved = true;
          } catch (const SegmentationError&) {
            // keep the first pass
          }
        }
      }
      if (!moved) break;
    }
  }

  /// One attempt, timed under `kind`.
  Attempt attempt(double mu, bool refine_on_seed_slice) {
    AttemptCost& cost = costs[kind];
    ++cost.count;
    struct Timer {
      AttemptCost& cost;
      std::chrono::steady_clock::time_point t0 = std::chrono::steady_clock::now();
      ~Timer() { cost.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); }
    } timer{cost};
    return attempt_body(mu, refine_on_seed_slice);
  }

  /// The start section with the window centred on `mu` (refined on the start slice's own median
  /// when `refine_on_seed_slice`), then propagation both ways from it.
  Attempt attempt_body(double mu, bool refine_on_seed_slice) {
    StartSection start = start_section(c, k0, s, p, mu, refine_on_seed_slice, seed_margin);
    Start st{std::move(start.fit), start.lo, start.hi, start.mu, k0, {}};
    const Fit& f0 = st.f0;
    if (f0.area_mm2 < p.min_area_mm2 || f0.area_mm2 > p.max_area_mm2) {
      char b[256];
      std::snprintf(b, sizeof b, "%s not found at seed %s: the contour %s (%.0f mm², expected %.0f–%.0f mm²)",
                    p.organ.c_str(), fmt_mm(seed_lps).c_str(), f0.area_mm2 < p.min_area_mm2 ? "collapsed" : "leaked",
                    f0.area_mm2, p.min_area_mm2, p.max_area_mm2);
      throw SegmentationError(ExitCode::organ_not_found, b, "check that the seed lies inside the " + p.organ);
    }
    // The organ's coarse 3-D region in the same window: where the organ continues on the next
    // slice, and the start contour there.
    seg::Region3dOptions ro;
    ro.lo_hu = st.lo;
    ro.hi_hu = st.hi;
    ro.sigma_mm = region_sigma_mm(p, c);
    ro.open_mm = std::max(p.region_open_mm, std::min(c.sx, c.sy));
    ro.half_width_mm = std::sqrt(p.max_area_mm2 / M_PI) + 20.0;
    ro.half_length_mm = p.max_length_mm;
    st.region = seg::grow_region3d(vol, std::llround(ijk.x()), std::llround(ijk.y()), k0, ro);
    Direction up, down;
    if (parallel)
      tbb::parallel_invoke([&] { up = propagate(st, +1, f0.pts); }, [&] { down = propagate(st, -1, f0.pts); });
    else {
      up = propagate(st, +1, f0.pts);
      down = propagate(st, -1, f0.pts);
    }
    if (p.guide_core_fraction > 0) {
      const std::vector<SliceContour> up0 = up.acc, down0 = down.acc;
      redo_from_core(st, +1, up, down0);
      redo_from_core(st, -1, down, up0);
    }
    Attempt at;
    at.all.assign(down.acc.rbegin(), down.acc.rend());
    at.all.push_back({k0, f0.pts});
    at.all.insert(at.all.end(), up.acc.begin(), up.acc.end());
    at.note_up = up.note;
    at.note_down = down.note;
    at.held.assign(down.held.rbegin(), down.held.rend());
    at.held.insert(at.held.end(), up.held.begin(), up.held.end());
    at.lo = st.lo;
    at.hi = st.hi;
    at.mu = st.mu;
    return at;
  }

  /// Slice after slice from the start section in direction `dir` (+1 or −1), each slice started
  /// from `seed_guide` or the section before, until a stop rule (detail/section_rules.h) fires.
  Direction propagate(const Start& st, int dir, const std::vector<Point2>& seed_guide) {
    const ImageGrid& g = vol.grid;
    const std::int64_t K = g.size_vox[2];
    Direction d;
    std::vector<Point2> prev = st.f0.pts;
    double prev_area = st.f0.area_mm2;
    // Where the next slice starts from, and what its start decisions compare with: the previous
    // section, less any part of it that lay off the section before (a lobe there is a neighbour
    // joined in below the leak tests' limits more often than the organ).
    std::vector<Point2> guide = seed_guide;
    // The organ's drift between slices (centroid of the last section less the one before).
    Point2 drift{0, 0};
    int held_in_a_row = 0;
    std::vector<Point2> anchor;  // the last section found unaided, while the slice before was held
    double anchor_area = 0;
    // Slices held within reach just before the stop stay: on thick noisy slices the held slice is
    // most often the organ's last small section (the fundus against the liver), not a neighbour
    // past its end; dropping them had cost up to 0.08 Dice on noisier such runs (segmentation
    // README).
    // Areas of the slices behind, for the leak test over at least area_ratio_span_mm (thin slices
    // let a leak grow by a few per cent a slice, each step under the ratio).
    std::vector<double> areas{st.f0.area_mm2};
    const std::size_t span = std::size_t(std::max(1.0, std::floor(p.area_ratio_span_mm / g.spacing_mm.z() + 1e-9)));
    for (std::int64_t k = st.k0 + dir; k >= 0 && k < K; k += dir) {
      progress.check_cancelled();
      progress.report(std::min(0.99, double(++done) / 40.0), "segmenting " + p.organ);
      // Start inside the neighbour's contour, so the pressure grows it out to this slice's edge
      // rather than having to pull a too-large start back.
      std::vector<Point2> init = scaled(guide, 0.7);
      // Where the 3-D region continues under the previous contour (a section that moved
      // sideways, as a fundus does between thick slices), start from its shrunken outline.
      const cv::Mat under = seg::region_under(st.region, k, guide, c.sx, c.sy, p.region_reach_mm);
      double a_under = 0;
      bool from_region = false;
      if (!under.empty()) {
        a_under = cv::countNonZero(under) * c.sx * c.sy;
        const std::vector<Point2> outline = seg::mask_outline_mm(st.region, under, c.sx, c.sy);
        if (a_under >= p.min_area_mm2 && a_under <= p.max_area_ratio * prev_area && outline.size() >= 4)
          init = scaled(outline, 0.7), from_region = true;
      }
      const double m_init = median_inside(c, k, init);
      if (!(m_init >= st.lo && m_init <= st.hi)) {
        d.note = "stopped at slice " + std::to_string(k) + ": the region left the organ's HU window";
        return d;
      }
      Fit f = fit_slice(c, k, init, p, st.lo, st.hi, p.roi_margin_mm, opening_for(p, prev_area));
      if (from_region && p.continuity_margin_mm > 0) {
        // The region may have joined a neighbour (duodenum through a wall that noise hides); a
        // start inside the previous section is tried too, and the section that continues the
        // previous one more is kept: its area within the shift tolerance of the previous
        // section less its area beyond (a larger section is not better for lying off it).
        Fit inside = fit_slice(c, k, scaled(guide, 0.7), p, st.lo, st.hi, p.roi_margin_mm, opening_for(p, prev_area));
        auto on_prev = [&](const Fit& x) {
          return x.area_mm2 * (1.0 - 2.0 * area_outside(x.pts, guide, p.shift_tolerance_mm, c.sx, c.sy));
        };
        if (inside.area_mm2 >= p.min_area_mm2 && on_prev(inside) > on_prev(f)) f = std::move(inside);
      } else if (from_region &&
          area_outside(f.pts, prev, p.shift_tolerance_mm, c.sx, c.sy) > p.max_shifted_fraction) {
        // Started from the region's outline the snake slid onto another structure: start again
        // inside the previous section.
        Fit again = fit_slice(c, k, scaled(guide, 0.7), p, st.lo, st.hi, p.roi_margin_mm, opening_for(p, prev_area));
        if (again.area_mm2 >= p.min_area_mm2 &&
            area_outside(again.pts, prev, p.shift_tolerance_mm, c.sx, c.sy) <= p.max_shifted_fraction)
          f = std::move(again);
      }
      // Whether this slice's section continues the organ (the stop rules: detail/section_rules.h).
      std::vector<Point2> moved_prev;
      for (const auto& q : prev) moved_prev.push_back({q.x + drift.x, q.y + drift.y});
      seg::SectionHistory history;
      history.previous = &prev;
      history.previous_area_mm2 = prev_area;
      history.earlier_area_mm2 = areas[areas.size() > span ? areas.size() - span : 0];
      history.previous_moved = &moved_prev;
      history.unaided = &anchor;
      history.unaided_area_mm2 = anchor_area;
      history.region_area_mm2 = a_under;
      history.organ_mean_hu = st.mu;
      history.sx = c.sx, history.sy = c.sy;
      auto judge = [&](const Fit& x) {
        return seg::judge_section({&x.pts, x.area_mm2, x.edge_support}, history, p,
                                  [&] { return median_inside(c, k, x.pts); });
      };
      seg::SectionStop stop = judge(f);
      if (seg::is_leak(stop) && p.continuity_margin_mm > 0 && held_in_a_row < p.max_held_in_a_row) {
        // A leak need not end the organ: the continuity hold fits the slice again within reach
        // of the previous section, and the organ goes on if that section passes every rule.
        std::optional<Fit> held =
            continuity_hold(c, k, moved_prev, p, st.lo, st.hi, opening_for(p, prev_area), g.spacing_mm.z());
        if (held && judge(*held) == seg::SectionStop::none) {
          if (held_in_a_row == 0) anchor = prev, anchor_area = prev_area;
          f = std::move(*held);
          stop = seg::SectionStop::none;
          ++held_in_a_row;
          d.held.push_back(k);
        }
      } else if (stop == seg::SectionStop::none) {
        held_in_a_row = 0;
        anchor.clear();
      }
      if (stop != seg::SectionStop::none) {
        d.note = seg::stop_note(stop, k);
        return d;
      }
      d.acc.push_back({k, f.pts});
      const Point2 c_prev = centroid(prev), c_new = centroid(f.pts);
      drift = {c_new.x - c_prev.x, c_new.y - c_prev.y};
      guide = f.pts;
      if (p.guide_core_fraction > 0) {
        auto [core, core_area] = part_within(f.pts, prev, p.shift_tolerance_mm, c.sx, c.sy);
        if (core.size() >= 8 && core_area >= p.min_area_mm2 && core_area >= p.guide_core_fraction * f.area_mm2)
          guide = std::move(core);
      }
      prev = f.pts;
      prev_area = f.area_mm2;
      areas.push_back(f.area_mm2);
    }
    d.note = std::string("reached the ") + (dir > 0 ? "last" : "first") + " slice";
    return d;
  }

  /// The start slice has no section before it: a lobe of a neighbour it took in can lead one
  /// direction onto that neighbour. Where part of the start's section lies off the first section
  /// found the other way (`other`), and the first section this way lies mostly on that part, this
  /// way is run again from the part that continues the other way.
  void redo_from_core(const Start& st, int dir, Direction& d, const std::vector<SliceContour>& other) {
    const Fit& f0 = st.f0;
    if (d.acc.empty() || other.empty()) return;
    auto [core, core_area] = part_within(f0.pts, other.front().pts, p.shift_tolerance_mm, c.sx, c.sy);
    if (core.size() < 8 || core_area < p.min_area_mm2 || core_area < p.guide_core_fraction * f0.area_mm2 ||
        core_area > 0.9 * f0.area_mm2)
      return;
    if (area_outside(d.acc.front().pts, core, p.shift_tolerance_mm, c.sx, c.sy) <= p.max_shifted_fraction) return;
    Direction again = propagate(st, dir, core);
    d.acc = std::move(again.acc), d.held = std::move(again.held);
    d.note = again.note + " (run again from the part of the seed's section that continues the other way)";
  }
};

OrganSegmentation segment_seeded(const Volume& vol, const OrganRequest& req, const OrganPreset& preset, bool parallel,
                                 Progress& progress) {
  OrganPreset p = preset;  // region smoothing adapts to the image below
  const ImageGrid& g = vol.grid;
  SliceCtx c(vol);
  OrganSegmentation out;
  out.organ = p.organ;
  out.label = p.label;
  Eigen::Vector3d ijk;
  Eigen::Vector3d seed_lps;
  if (req.seed_ijk) {
    ijk = Eigen::Vector3d(double((*req.seed_ijk)[0]), double((*req.seed_ijk)[1]), double((*req.seed_ijk)[2]));
    seed_lps = g.index_to_lps_mm(ijk);
  } else if (req.seed_lps_mm) {
    seed_lps = *req.seed_lps_mm;
    ijk = g.lps_mm_to_index(seed_lps);
  } else {
    throw SegmentationError(ExitCode::bad_seed, p.organ + ": a seed is required",
                            "give --seed X,Y,Z (LPS mm) or --seed-ijk I,J,K inside the " + p.organ);
  }
  out.seed_lps_mm = seed_lps;
  std::int64_t k0 = std::llround(ijk.z());  // the start slice (moved off a section too small to fit, below)
  if (!g.contains(std::llround(ijk.x()), std::llround(ijk.y()), k0))
    throw SegmentationError(ExitCode::bad_seed,
                            p.organ + " seed " + fmt_mm(seed_lps) + " lies outside the image",
                            "give a seed inside the image (see `organsmith info` for its extent)");
  const Point2 s = to_slice_mm(c, ijk);
  const double noise_hu = slice_noise_hu(c, k0, s, 40.0);
  adapt_to_noise(p, c, noise_hu);
  SeededRun run{vol, c, p, ijk, seed_lps, s, std::max(p.roi_margin_mm, std::sqrt(p.max_area_mm2 / M_PI) + 10.0), parallel,
                progress};
  run.k0 = k0;
  const double seed_med = run.hu_at_seed(k0);
  if (!run.seed_like(seed_med)) {
    char b[256];
    std::snprintf(b, sizeof b, "%s seed %s lies in tissue of median %.0f HU, outside the %s range [%.0f, %.0f] HU",
                  p.organ.c_str(), fmt_mm(seed_lps).c_str(), seed_med, p.organ.c_str(), p.seed_hu_lo, p.seed_hu_hi);
    throw SegmentationError(ExitCode::bad_seed, b,
                            "place the seed inside the " + p.organ + " (not in air, fat, bone or a neighbouring organ)");
  }
  const std::int64_t k_seed = k0;
  Attempt at = run.at_or_near_seed(k_seed, seed_med);
  const std::optional<std::string> start_note = run.for_a_longer_organ(at, k_seed);
  run.recentre(at);
  const auto& all = at.all;
  const double lo = at.lo, hi = at.hi, mu = at.mu;
  const std::string& note_up = at.note_up;
  const std::string& note_down = at.note_down;
  out.contours.organ = p.organ;
  for (const auto& sc : all) out.contours.contours.push_back(to_contour(vol, sc.k, sc.pts));
  out.first_slice = all.front().k;
  out.last_slice = all.back().k;
  char win[192];
  std::snprintf(win, sizeof win, "organ window %.0f to %.0f HU (median %.0f HU); noise %.0f HU, region smoothing %.2f px",
                lo, hi, mu, noise_hu, region_sigma_mm(p, c) / std::min(c.sx, c.sy));
  out.notes = {"towards k = 0: " + note_down, "towards k = " + std::to_string(g.size_vox[2] - 1) + ": " + note_up, win};
  out.window_lo_hu = lo, out.window_hi_hu = hi, out.region_sigma_mm = region_sigma_mm(p, c);
  if (!at.held.empty()) {
    std::string ks;
    for (const auto k : at.held) ks += (ks.empty() ? "" : ", ") + std::to_string(k);
    out.notes.push_back("leaked on slice(s) " + ks + "; fitted again within the previous section's reach");
  }
  if (run.k0 != k_seed)
    out.notes.push_back("started at slice " + std::to_string(run.k0) + ", " + std::to_string(std::llabs(run.k0 - k_seed)) +
                        " from the seed's: " + start_note.value_or("the section at the seed was too small to fit"));
  std::string cost_note;
  double total_s = 0;
  int total = 0;
  for (const char* kind : {"at the seed", "slid off the seed's slice", "for a longer organ", "recentred window"})
    if (const auto it = run.costs.find(kind); it != run.costs.end()) {
      char b[96];
      std::snprintf(b, sizeof b, "%s%d %s (%.2f s)", cost_note.empty() ? "" : ", ", it->second.count, kind, it->second.seconds);
      cost_note += b;
      total += it->second.count, total_s += it->second.seconds;
    }
  char b[64];
  std::snprintf(b, sizeof b, "%d propagation attempt%s, %.2f s: ", total, total == 1 ? "" : "s", total_s);
  out.notes.push_back(b + cost_note);
  return out;
}

// ---------------------------------------------------------------------------------------------
// Airway driver (the trachea): no seed. The air lumen that is round, near the body midline and runs along the body
// for at least min_length_mm is the trachea; it is followed caudally until it divides (carina).

struct Component {
  double area_mm2 = 0;
  Point2 centroid_mm;   // slice mm
  Point2 inner_mm;      // the pixel deepest inside (start of the snake)
  double inner_radius_mm = 0;
  double fill = 0, aspect = 0;
  bool touches_border = false;
  cv::Rect box;
  int id = 0;
};

struct AirSlice {
  cv::Mat labels;  // CV_32S, 0 = not air
  std::vector<Component> comps;
};

AirSlice air_components(const SliceCtx& c, std::int64_t k, double air_hu) {
  AirSlice a;
  cv::Mat m(c.H, c.W, CV_8U);
  const float* s = c.vol.slice(k);
  for (int y = 0; y < c.H; ++y) {
    auto* r = m.ptr<std::uint8_t>(y);
    for (int x = 0; x < c.W; ++x) r[x] = s[std::size_t(y) * c.W + x] < air_hu ? 1 : 0;
  }
  cv::Mat stats, cents;
  const int n = cv::connectedComponentsWithStats(m, a.labels, stats, cents, 4, CV_32S);
  const double px_area = c.sx * c.sy;
  for (int i = 1; i < n; ++i) {
    Component q;
    q.id = i;
    q.box = {stats.at<int>(i, cv::CC_STAT_LEFT), stats.at<int>(i, cv::CC_STAT_TOP), stats.at<int>(i, cv::CC_STAT_WIDTH),
             stats.at<int>(i, cv::CC_STAT_HEIGHT)};
    const int npx = stats.at<int>(i, cv::CC_STAT_AREA);
    q.area_mm2 = npx * px_area;
    q.centroid_mm = {cents.at<double>(i, 0) * c.sx, cents.at<double>(i, 1) * c.sy};
    q.touches_border = q.box.x == 0 || q.box.y == 0 || q.box.x + q.box.width == c.W || q.box.y + q.box.height == c.H;
    q.fill = double(npx) / (double(q.box.width) * q.box.height);
    const double bw = q.box.width * c.sx, bh = q.box.height * c.sy;
    q.aspect = std::max(bw, bh) / std::max(std::min(bw, bh), 1e-9);
    a.comps.push_back(q);
  }
  return a;
}

/// The component's pixels (255) in its bounding box with a one-pixel margin.
cv::Mat component_mask(const AirSlice& a, const Component& q) {
  cv::Mat mask = cv::Mat::zeros(q.box.height + 2, q.box.width + 2, CV_8U);
  for (int y = 0; y < q.box.height; ++y)
    for (int x = 0; x < q.box.width; ++x)
      if (a.labels.at<int>(q.box.y + y, q.box.x + x) == q.id) mask.at<std::uint8_t>(y + 1, x + 1) = 255;
  return mask;
}

/// The parts of at least min_part_mm2 left of an air component on slice k after an erosion by
/// radius_mm (the pixels whose centres lie farther than that from the nearest pixel outside;
/// square pixels, their geometric mean otherwise), each at least twice as wide as what parted
/// it (inscribed radius ≥ 2 × radius_mm) and lying at least half under `under` (a mask of the
/// slice), as their LPS centres, largest first: two lumens joined by a neck narrower than
/// 2 × radius_mm come apart; a round, D-shaped or compressed lumen stays one, and a crescent
/// (the posterior wall bulging in) that thins to a neck leaves horns too narrow to count.
std::vector<Eigen::Vector3d> lobes_after_erosion(const SliceCtx& c, std::int64_t k, const AirSlice& a,
                                                 const Component& q, double radius_mm, double min_part_mm2,
                                                 const cv::Mat& under) {
  cv::Mat dist;
  cv::distanceTransform(component_mask(a, q), dist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  const double px_mm = std::sqrt(c.sx * c.sy);
  cv::Mat core = dist > radius_mm / px_mm;
  cv::Mat labels, stats, cents;
  const int n = cv::connectedComponentsWithStats(core, labels, stats, cents, 8, CV_32S);
  std::vector<int> inside(static_cast<std::size_t>(n), 0);
  std::vector<float> widest(static_cast<std::size_t>(n), 0.0f);  // inscribed radius, pixels
  for (int y = 1; y + 1 < labels.rows; ++y)
    for (int x = 1; x + 1 < labels.cols; ++x) {
      const int l = labels.at<int>(y, x);
      if (!l) continue;
      widest[std::size_t(l)] = std::max(widest[std::size_t(l)], dist.at<float>(y, x));
      if (under.at<std::uint8_t>(q.box.y + y - 1, q.box.x + x - 1)) ++inside[std::size_t(l)];
    }
  std::vector<std::pair<int, Eigen::Vector3d>> parts;
  for (int i = 1; i < n; ++i) {
    const int area = stats.at<int>(i, cv::CC_STAT_AREA);
    if (area * c.sx * c.sy < min_part_mm2 || 2 * inside[std::size_t(i)] < area ||
        widest[std::size_t(i)] * px_mm < 2 * radius_mm)
      continue;
    const Eigen::Vector3d at(q.box.x + cents.at<double>(i, 0) - 1, q.box.y + cents.at<double>(i, 1) - 1, double(k));
    parts.emplace_back(area, c.vol.grid.index_to_lps_mm(at));
  }
  std::sort(parts.begin(), parts.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
  std::vector<Eigen::Vector3d> out;
  for (const auto& pr : parts) out.push_back(pr.second);
  return out;
}

void find_inner_point(const SliceCtx& c, const AirSlice& a, Component& q) {
  cv::Mat mask = component_mask(a, q);
  cv::Mat d;
  cv::distanceTransform(mask, d, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  double mx;
  cv::Point loc;
  cv::minMaxLoc(d, nullptr, &mx, nullptr, &loc);
  q.inner_mm = {(q.box.x + loc.x - 1) * c.sx, (q.box.y + loc.y - 1) * c.sy};
  q.inner_radius_mm = mx * std::min(c.sx, c.sy);
}

/// Outline (slice mm) of an air component eroded by one pixel: the largest outer contour of the
/// eroded mask, through pixel centres. Empty when nothing survives the erosion.
std::vector<Point2> air_region_outline(const SliceCtx& c, const AirSlice& a, const Component& q) {
  cv::Mat mask = component_mask(a, q);
  cv::erode(mask, mask, cv::getStructuringElement(cv::MORPH_RECT, {3, 3}));
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  std::size_t best = contours.size();
  double best_area = 0;
  for (std::size_t i = 0; i < contours.size(); ++i) {
    const double ar = cv::contourArea(contours[i]);
    if (ar > best_area) best_area = ar, best = i;
  }
  std::vector<Point2> out;
  if (best == contours.size() || contours[best].size() < 8) return out;
  for (const cv::Point& pt : contours[best]) out.push_back({(q.box.x + pt.x - 1) * c.sx, (q.box.y + pt.y - 1) * c.sy});
  return out;
}

/// Left–right position (mm, along the patient's L axis) of the body's centre in slice k.
double body_centre_l(const SliceCtx& c, std::int64_t k) {
  const float* s = c.vol.slice(k);
  double sum = 0;
  std::int64_t n = 0;
  for (int y = 0; y < c.H; y += 2)
    for (int x = 0; x < c.W; x += 2)
      if (s[std::size_t(y) * c.W + x] > -300.0f) {
        sum += c.vol.grid.index_to_lps_mm({double(x), double(y), double(k)}).x();
        ++n;
      }
  return n ? sum / double(n) : c.vol.grid.index_to_lps_mm({c.W / 2.0, c.H / 2.0, double(k)}).x();
}

OrganSegmentation segment_airway(const Volume& vol, const OrganPreset& p, bool parallel, Progress& progress) {
  const ImageGrid& g = vol.grid;
  SliceCtx c(vol);
  OrganSegmentation out;
  out.organ = p.organ;
  out.label = p.label;
  const std::int64_t K = g.size_vox[2];
  // Slices from cranial to caudal.
  std::vector<std::int64_t> order(static_cast<std::size_t>(K));
  std::iota(order.begin(), order.end(), 0);
  const bool k_up_is_cranial = g.index_to_lps_mm({0, 0, 1}).z() > g.index_to_lps_mm({0, 0, 0}).z();
  if (k_up_is_cranial) std::reverse(order.begin(), order.end());
  // Candidates per slice.
  std::vector<std::vector<Component>> cands(static_cast<std::size_t>(K));
  auto find = [&](std::int64_t k) {
    AirSlice a = air_components(c, k, p.air_hu);
    const double mid = body_centre_l(c, k);
    for (Component& q : a.comps) {
      if (q.touches_border || q.area_mm2 < p.min_area_mm2 || q.area_mm2 > p.max_area_mm2 || q.fill < p.min_fill ||
          q.aspect > p.max_aspect)
        continue;
      const double l = g.index_to_lps_mm({q.centroid_mm.x / c.sx, q.centroid_mm.y / c.sy, double(k)}).x();
      if (std::abs(l - mid) > p.max_midline_offset_mm) continue;
      cands[std::size_t(k)].push_back(q);
    }
  };
  if (parallel)
    tbb::parallel_for(std::int64_t(0), K, [&](std::int64_t k) { find(k); });
  else
    for (std::int64_t k = 0; k < K; ++k) find(k);
  progress.report(0.3, "finding the trachea");
  progress.check_cancelled();
  // The most cranial candidate that continues (centroid within a lumen radius or 10 mm) for at
  // least min_length_mm of slices.
  const double dz = g.spacing_mm.z();
  const int need = std::max(2, int(std::ceil(p.min_length_mm / dz)) + 1);
  std::size_t start = order.size();
  Component start_comp;
  for (std::size_t oi = 0; oi < order.size() && start == order.size(); ++oi) {
    for (const Component& q : cands[std::size_t(order[oi])]) {
      Point2 at = q.centroid_mm;
      int run = 1;
      for (std::size_t oj = oi + 1; oj < order.size() && run < need; ++oj) {
        bool found = false;
        for (const Component& r : cands[std::size_t(order[oj])])
          if (std::hypot(r.centroid_mm.x - at.x, r.centroid_mm.y - at.y) < 10.0) {
            at = r.centroid_mm;
            found = true;
            break;
          }
        if (!found) break;
        ++run;
      }
      if (run >= need) {
        start = oi;
        start_comp = q;
        break;
      }
    }
  }
  if (start == order.size())
    throw SegmentationError(ExitCode::organ_not_found,
                            "trachea not found: no round air lumen near the body midline continues for " +
                                std::to_string(int(p.min_length_mm)) + " mm",
                            "the scan must include the chest above the carina; check the series with `organsmith info`");
  // Follow the lumen caudally.
  std::vector<SliceContour> acc;
  std::vector<Point2> prev_pts;
  double prev_area = 0;
  std::string note = "reached the last slice";
  // Whether at[0] (LPS) lies beside any other of `at`, left or right rather than behind or above.
  const auto divides = [](const std::vector<Eigen::Vector3d>& at) {
    for (std::size_t j = 1; j < at.size(); ++j) {
      const Eigen::Vector3d d = at[j] - at[0];
      if (std::abs(d.x()) >= std::hypot(d.y(), d.z())) return true;
    }
    return false;
  };
  for (std::size_t oi = start; oi < order.size(); ++oi) {
    progress.check_cancelled();
    progress.report(0.3 + 0.7 * double(oi - start) / double(order.size() - start), "segmenting trachea");
    const std::int64_t k = order[oi];
    AirSlice a = air_components(c, k, p.air_hu);
    Component comp;
    if (oi == start) {
      comp = start_comp;
    } else {
      // Air components overlapping the previous lumen, or the lumen divide_span_mm back: on
      // thin slices the bronchi part gradually, and the second one may appear only once the
      // contour above has already narrowed to the first.
      std::map<int, int> overlap;
      cv::Mat under = cv::Mat::zeros(c.H, c.W, CV_8U);  // the previous lumen
      const std::size_t back = std::size_t(std::max(1.0, std::floor(p.divide_span_mm / g.spacing_mm.z() + 1e-9)));
      for (const auto* pts : {&prev_pts, &acc[acc.size() > back ? acc.size() - back : 0].pts}) {
        std::map<int, int> here;
        const bool is_prev = pts == &prev_pts;
        seg::rasterise(to_px(c, *pts), c.W, c.H, [&](int x, int y) {
          if (is_prev) under.at<std::uint8_t>(y, x) = 1;
          const int l = a.labels.at<int>(y, x);
          if (l) ++here[l];
        });
        for (const auto& [l, n] : here) overlap[l] = std::max(overlap[l], n);
      }
      // Most overlap first.
      std::vector<std::pair<int, Component>> hits;
      for (const auto& [l, n] : overlap) {
        const Component& q = a.comps[std::size_t(l - 1)];
        if (q.area_mm2 >= 0.25 * p.min_area_mm2 && !q.touches_border) hits.emplace_back(n, q);
      }
      std::stable_sort(hits.begin(), hits.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
      if (hits.empty()) {
        note = "stopped at slice " + std::to_string(k) + ": the lumen ends";
        break;
      }
      // The main bronchi leave the carina side by side, left and right. A second air region under
      // the lumen behind or in front of it (the oesophagus, joined to the lumen on the slice
      // above through a thin wall) is left out and the lumen followed on.
      std::vector<Eigen::Vector3d> hit_at;
      for (const auto& h : hits)
        hit_at.push_back(g.index_to_lps_mm({h.second.centroid_mm.x / c.sx, h.second.centroid_mm.y / c.sy, double(k)}));
      if (divides(hit_at)) {
        note = "stopped at slice " + std::to_string(k) + ": the lumen divides (carina)";
        break;
      }
      comp = hits.front().second;
      // A thick slice across the carina averages the two bronchi below it with the lumen above:
      // at −500 HU they join through the ridge's partial volume, by a neck that narrows with the
      // share of the slice below the ridge. Two lobes that an erosion of a fraction of the slice
      // thickness parts, each under the lumen above and side by side left–right as the main
      // bronchi leave the carina, are the divided lumen; air joined behind or in front of the
      // lumen (the oesophagus through a thin wall) is not.
      const double neck_mm = p.divide_neck_slice_fraction * g.spacing_mm.z();
      if (neck_mm > 0) {
        const auto lobes = lobes_after_erosion(c, k, a, comp, neck_mm, 0.25 * p.min_area_mm2, under);
        if (divides(lobes)) {
          char why[160];
          std::snprintf(why, sizeof why,
                        "stopped at slice %lld: the lumen divides (carina; two lobes side by side joined by a neck "
                        "under %.1f mm)",
                        static_cast<long long>(k), 2 * neck_mm);
          note = why;
          break;
        }
      }
      if (comp.area_mm2 > p.max_area_ratio * prev_area) {
        note = "stopped at slice " + std::to_string(k) + ": the lumen widens into the bronchi or lungs";
        break;
      }
    }
    // The snake starts from the detected air region itself (its outline one pixel inside), so it
    // only has to seat the outline on the −500 HU boundary with sub-pixel precision, whatever
    // the lumen's shape (round, horseshoe, compressed); a small circle at the deepest point is
    // the fallback for a region too thin to erode.
    std::vector<Point2> init = air_region_outline(c, a, comp);
    if (init.size() < 8) {
      find_inner_point(c, a, comp);
      init = seg::circle(comp.inner_mm, std::clamp(0.5 * comp.inner_radius_mm, 1.0, p.start_radius_mm), 16);
    }
    Fit f = fit_slice(c, k, init, p, p.air_hu - p.region_below_hu, p.air_hu,
                      std::max(p.roi_margin_mm, std::sqrt(comp.area_mm2)), p.region_open_mm);
    if (f.area_mm2 < p.min_area_mm2 * 0.25) {
      note = "stopped at slice " + std::to_string(k) + ": the lumen collapses";
      break;
    }
    acc.push_back({k, f.pts});
    prev_pts = f.pts;
    prev_area = std::max(f.area_mm2, comp.area_mm2);
  }
  std::sort(acc.begin(), acc.end(), [](const auto& a, const auto& b) { return a.k < b.k; });
  out.contours.organ = p.organ;
  for (const auto& sc : acc) out.contours.contours.push_back(to_contour(vol, sc.k, sc.pts));
  out.first_slice = acc.front().k;
  out.last_slice = acc.back().k;
  out.seed_lps_mm = g.index_to_lps_mm({start_comp.centroid_mm.x / c.sx, start_comp.centroid_mm.y / c.sy, double(order[start])});
  out.notes = {"found at slice " + std::to_string(order[start]) + " (most cranial round midline air lumen)",
               "caudal end: " + note};
  return out;
}

/// The 3-D GVF surface from the slices' result of a seeded organ (presets surface3d*): its label
/// replaces the slices' (never over another organ's voxels), and each slice's contour becomes the
/// outline of the largest section of the surface there. Returns the organ's voxel count.
std::int64_t surface_from_slices(const Volume& vol, const OrganPreset& p, OrganSegmentation& o, LabelMap& labels,
                                 bool parallel) {
  const seg::BoxMask start = seg::box_mask_of(labels.labels.data(), vol.grid, std::uint8_t(o.label));
  seg::Surface3dOptions so;
  so.lo_hu = o.window_lo_hu, so.hi_hu = o.window_hi_hu, so.ramp_hu = p.pressure_ramp_hu;
  so.region_sigma_mm = o.region_sigma_mm;
  so.edge_lo_hu = p.edge_window_lo_hu, so.edge_hi_hu = p.edge_window_hi_hu, so.edge_sigma_mm = p.edge_sigma_mm;
  so.gvf_mu = p.gvf_mu;
  so.gvf_weight = p.surface3d_gvf_weight, so.curvature_mm = p.surface3d_curvature_mm;
  so.max_grow_mm = p.surface3d_max_grow_mm, so.max_steps = p.surface3d_max_steps;
  so.edge_stop_hu_per_mm = p.surface3d_edge_stop_hu_per_mm;
  so.local_radius_mm = p.surface3d_local_radius_mm, so.min_contrast_hu = p.surface3d_min_contrast_hu;
  so.contrast_curvature_hu = p.surface3d_contrast_curvature_hu;
  so.open_start_mm = p.surface3d_open_start_mm;
  so.parallel = parallel;
  const seg::Surface3dResult r = seg::evolve_surface3d(vol, start, so);
  // The start lies in the surface's box: the slices' voxels leave, the surface's join.
  const auto& g = vol.grid;
  const auto& box = r.mask;
  std::int64_t n = 0;
  std::size_t b = 0;
  for (std::int64_t k = 0; k < box.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < box.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < box.size_vox[0]; ++i, ++b) {
        const std::int64_t I = box.origin_vox[0] + i, J = box.origin_vox[1] + j, K = box.origin_vox[2] + k;
        std::uint8_t& l = labels.labels[std::size_t(g.offset(I, J, K))];
        if (start.at(I, J, K)) l = 0;
        if (box.inside[b] && l == 0) l = std::uint8_t(o.label), ++n;
      }
  const int W = int(g.size_vox[0]), H = int(g.size_vox[1]);
  o.contours.contours.clear();
  for (std::int64_t k = r.first_k; k <= r.last_k; ++k) {
    cv::Mat m(H, W, CV_8U, cv::Scalar(0));
    const std::uint8_t* sl = labels.labels.data() + k * g.slice_voxel_count();
    bool any = false;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        if (sl[std::size_t(y) * W + x] == o.label) m.at<std::uint8_t>(y, x) = 255, any = true;
    if (!any) continue;
    const auto pts = seg::mask_outline_mm(m, 0.0, 0.0, g.spacing_mm.x(), g.spacing_mm.y());
    if (pts.size() >= 3) o.contours.contours.push_back(to_contour(vol, k, pts));
  }
  if (!o.contours.contours.empty()) {
    o.first_slice = o.contours.contours.front().slice_k;
    o.last_slice = o.contours.contours.back().slice_k;
  }
  o.notes.push_back(r.note);
  return n;
}

}  // namespace

SegmentationResult segment_organs(const Volume& volume, const std::vector<OrganRequest>& organs,
                                  const SegmentOptions& options, Progress& progress) {
  volume.grid.validate();
  auto presets = default_organ_presets();
  if (!options.registry_toml.empty())
    presets = parse_organ_presets(options.registry_toml, std::move(presets), PresetText::registry);
  if (!options.preset_overrides_toml.empty())
    presets = parse_organ_presets(options.preset_overrides_toml, std::move(presets));
  std::vector<const OrganPreset*> ps;
  for (const auto& r : organs) {
    auto it = presets.find(r.organ);
    if (it == presets.end())
      throw SegmentationError(ExitCode::organ_not_found, "no preset for organ '" + r.organ + "'",
                              "organs with a segmentation preset are those with a [<organ>.segment] table in the registry "
                              "(data/organs.toml or the case's own); others come from a label map");
    ps.push_back(&it->second);
  }
  if (volume.grid.size_vox[0] < 8 || volume.grid.size_vox[1] < 8)
    throw SegmentationError(ExitCode::organ_not_found, "the image is too small to segment (under 8 × 8 pixels per slice)");
  SegmentationResult res;
  res.organs.resize(organs.size());
  auto one = [&](std::size_t i) {
    const OrganPreset& p = *ps[i];
    // The registry's driver; an organ given a seed is segmented from it whatever its driver.
    const bool seeded = p.driver != "airway" || organs[i].seed_lps_mm || organs[i].seed_ijk;
    res.organs[i] = seeded ? segment_seeded(volume, organs[i], p, options.parallel, progress)
                           : segment_airway(volume, p, options.parallel, progress);
  };
  if (options.parallel && organs.size() > 1)
    tbb::parallel_for(std::size_t(0), organs.size(), one);
  else
    for (std::size_t i = 0; i < organs.size(); ++i) one(i);
  // Label assembly: each contour filled on its slice.
  res.labels.grid = volume.grid;
  res.labels.labels.assign(std::size_t(volume.grid.voxel_count()), 0);
  SliceCtx c(volume);
  for (auto& o : res.organs) {
    std::int64_t n = 0;
    for (const Contour& ct : o.contours.contours) {
      std::vector<Point2> px;
      for (const auto& q : ct.points_lps_mm) {
        const Eigen::Vector3d ijk = volume.grid.lps_mm_to_index(q);
        px.push_back({ijk.x(), ijk.y()});
      }
      std::uint8_t* s = res.labels.labels.data() + ct.slice_k * volume.grid.slice_voxel_count();
      seg::rasterise(px, c.W, c.H, [&](int x, int y) {
        s[std::size_t(y) * c.W + x] = o.label;
        ++n;
      });
    }
    if (n == 0)
      throw SegmentationError(ExitCode::organ_not_found, o.organ + ": the contours enclose no voxel",
                              "check the seed and the organ presets");
    const OrganPreset& p = presets.at(o.organ);
    if (p.surface3d && o.window_hi_hu > o.window_lo_hu) n = surface_from_slices(volume, p, o, res.labels, options.parallel);
    o.volume_ml = double(n) * volume.grid.spacing_mm.prod() / 1000.0;
  }
  progress.report(1.0, "segmentation done");
  return res;
}

std::string contours_json(const OrganSegmentation& organ) {
  nlohmann::json j;
  j["organ"] = organ.organ;
  j["label"] = organ.label;
  j["frame"] = "LPS";
  j["unit"] = "mm";
  j["contours"] = nlohmann::json::array();
  for (const auto& c : organ.contours.contours) {
    nlohmann::json pts = nlohmann::json::array();
    for (const auto& p : c.points_lps_mm) {
      // 4 decimals (0.1 µm): enough, and keeps the text byte-identical across runs.
      auto r = [](double v) { return std::round(v * 1e4) / 1e4; };
      pts.push_back({r(p.x()), r(p.y()), r(p.z())});
    }
    j["contours"].push_back({{"slice_k", c.slice_k}, {"closed", c.closed}, {"points_lps_mm", pts}});
  }
  return j.dump(1) + "\n";
}

std::optional<ContourStack> contours_from_json(const std::string& text, const std::string& organ, std::string* why) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (!j.is_object() || !j.contains("contours") || !j["contours"].is_array()) return std::nullopt;
  ContourStack stack;
  stack.organ = j.value("organ", organ);
  try {
    for (const auto& c : j["contours"]) {
      Contour contour;
      contour.slice_k = c.value("slice_k", std::int64_t(0));
      contour.closed = c.value("closed", true);
      for (const auto& q : c.at("points_lps_mm")) contour.points_lps_mm.emplace_back(q.at(0), q.at(1), q.at(2));
      stack.contours.push_back(std::move(contour));
    }
  } catch (const std::exception& e) {
    if (why) *why = std::string("contours not in the expected form: ") + e.what();
    return std::nullopt;
  }
  return stack;
}

}  // namespace organsmith
