#include "segmentation/detail/section_rules.h"

#include "segmentation/detail/region3d.h"
#include "segmentation/slice_ops.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace organsmith::seg {

namespace {

/// Contours `a` and `b` (slice mm) rasterised on one pixel grid, `b` dilated by `tol_mm`.
struct PairRaster {
  cv::Mat a, b;
  double x0 = 0, y0 = 0;
  int pad = 0;
};

PairRaster raster_pair(const std::vector<Point2>& a, const std::vector<Point2>& b, double tol_mm, double sx, double sy) {
  PairRaster r;
  double x1 = -1e300, y1 = -1e300;
  r.x0 = r.y0 = 1e300;
  for (const auto* c : {&a, &b})
    for (const auto& p : *c) r.x0 = std::min(r.x0, p.x), r.y0 = std::min(r.y0, p.y), x1 = std::max(x1, p.x), y1 = std::max(y1, p.y);
  r.pad = int(std::ceil(tol_mm / std::min(sx, sy))) + 2;
  const int w = int(std::ceil((x1 - r.x0) / sx)) + 2 * r.pad + 1, h = int(std::ceil((y1 - r.y0) / sy)) + 2 * r.pad + 1;
  auto to_px = [&](const std::vector<Point2>& c) {
    std::vector<Point2> q;
    for (const auto& p : c) q.push_back({(p.x - r.x0) / sx + r.pad, (p.y - r.y0) / sy + r.pad});
    return q;
  };
  r.a = cv::Mat::zeros(h, w, CV_8U);
  r.b = cv::Mat::zeros(h, w, CV_8U);
  rasterise(to_px(a), w, h, [&](int x, int y) { r.a.at<std::uint8_t>(y, x) = 255; });
  rasterise(to_px(b), w, h, [&](int x, int y) { r.b.at<std::uint8_t>(y, x) = 255; });
  if (tol_mm > 0) {
    const int rx = std::max(1, int(std::lround(tol_mm / sx))), ry = std::max(1, int(std::lround(tol_mm / sy)));
    cv::dilate(r.b, r.b, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * rx + 1, 2 * ry + 1}));
  }
  return r;
}

}  // namespace

/// Fraction of the area inside contour `a` that lies farther than `tol_mm` outside contour `b`
/// (both in slice mm): how much of a new section is not a continuation of the previous one.
double area_outside(const std::vector<Point2>& a, const std::vector<Point2>& b, double tol_mm, double sx, double sy) {
  if (a.size() < 3 || b.size() < 3) return 0.0;
  const PairRaster r = raster_pair(a, b, tol_mm, sx, sy);
  const int n = cv::countNonZero(r.a);
  if (n == 0) return 0.0;
  cv::Mat out;
  cv::bitwise_and(r.a, ~r.b, out);
  return double(cv::countNonZero(out)) / n;
}

/// The part of section `a` within `tol_mm` of section `b` (its largest piece, as a contour of
/// boundary-pixel centres in slice mm), and that part's area in mm²; empty where none.
std::pair<std::vector<Point2>, double> part_within(const std::vector<Point2>& a, const std::vector<Point2>& b, double tol_mm,
                                                   double sx, double sy) {
  if (a.size() < 3 || b.size() < 3) return {};
  const PairRaster r = raster_pair(a, b, tol_mm, sx, sy);
  cv::Mat in;
  cv::bitwise_and(r.a, r.b, in);
  cv::Mat lab, stats, centres;
  const int n = cv::connectedComponentsWithStats(in, lab, stats, centres, 4);
  int best = 0;
  for (int i = 1; i < n; ++i)
    if (best == 0 || stats.at<int>(i, cv::CC_STAT_AREA) > stats.at<int>(best, cv::CC_STAT_AREA)) best = i;
  if (best == 0) return {};
  std::vector<Point2> out = mask_outline_mm(lab == best, r.x0 - r.pad * sx, r.y0 - r.pad * sy, sx, sy);
  if (out.size() < 4) return {};
  return {out, stats.at<int>(best, cv::CC_STAT_AREA) * sx * sy};
}

bool is_leak(SectionStop stop) {
  return stop == SectionStop::area_jumped || stop == SectionStop::grew_off_previous ||
         stop == SectionStop::drifted_off_previous || stop == SectionStop::grew_off_unaided;
}

std::string stop_note(SectionStop stop, std::int64_t k) {
  const std::string at = "stopped at slice " + std::to_string(k) + ": ";
  switch (stop) {
    case SectionStop::none: return {};
    case SectionStop::collapsed: return at + "area collapsed";
    case SectionStop::area_jumped: return at + "area jumped (leak into a neighbour)";
    case SectionStop::grew_off_previous: return at + "the section grew off the previous one (leak into a neighbour)";
    case SectionStop::drifted_off_previous: return at + "the section lies off the previous one (drifted onto a neighbour)";
    case SectionStop::grew_off_unaided:
      return at + "the section grew off the last section found unaided (leak into a neighbour)";
    case SectionStop::edge_support_lost: return at + "edge support lost (no wall around most of the contour)";
    case SectionStop::intensity_drifted: return at + "intensity drifted from the organ's";
  }
  return {};
}

SectionStop judge_section(const Section& f, const SectionHistory& h, const OrganPreset& p,
                          const std::function<double()>& median_hu) {
  // A section smaller than the organ's smallest: the organ has ended (or the snake collapsed).
  if (f.area_mm2 < p.min_area_mm2) return SectionStop::collapsed;
  // A section much larger than the one before (or than the one area_ratio_span_mm behind, as
  // thin slices let a leak grow by a few per cent a slice, each step under the ratio) has
  // leaked into a neighbour.
  if (f.area_mm2 > p.max_area_mm2 || f.area_mm2 > p.max_area_ratio * h.previous_area_mm2 ||
      f.area_mm2 > p.max_area_ratio * h.earlier_area_mm2)
    return SectionStop::area_jumped;
  // A section that grows while much of it lies off the previous one is a neighbour joined in (a
  // bowel loop beside a tapering fundus between thick slices), not the organ going on.
  if (f.area_mm2 > p.shift_growth_ratio * h.previous_area_mm2 &&
      area_outside(*f.pts, *h.previous, p.shift_tolerance_mm, h.sx, h.sy) > p.max_shifted_fraction)
    return SectionStop::grew_off_previous;
  // With a continuity margin, a section that does not grow and lies mostly off the previous one
  // (moved by the organ's drift) is a neighbour: the contour drifted onto bowel beside the organ
  // where the organ tapers (growing sections are the test above).
  if (p.continuity_margin_mm > 0 && f.area_mm2 <= h.previous_area_mm2 &&
      area_outside(*f.pts, *h.previous_moved, p.shift_tolerance_mm, h.sx, h.sy) > p.max_shifted_fraction)
    return SectionStop::drifted_off_previous;
  // After a slice held within reach, the section must also continue the last section found
  // unaided: a held section past the organ's end does not vouch for the next one.
  if (h.unaided && !h.unaided->empty() && f.area_mm2 > p.shift_growth_ratio * h.unaided_area_mm2 &&
      area_outside(*f.pts, *h.unaided, p.shift_tolerance_mm, h.sx, h.sy) > p.max_shifted_fraction)
    return SectionStop::grew_off_unaided;
  // A wall that is not visible all round (bile against liver of close HU on a noisy scan) ends
  // the organ only where its 3-D region ends too.
  const bool region_goes_on = h.region_area_mm2 >= 0.5 * f.area_mm2 && h.region_area_mm2 <= p.max_area_ratio * h.previous_area_mm2;
  if (f.edge_support < p.min_edge_support && !region_goes_on) return SectionStop::edge_support_lost;
  // A section whose tissue is no longer the organ's (its median off the organ's mean).
  if (!(std::abs(median_hu() - h.organ_mean_hu) <= p.max_mean_drift_hu)) return SectionStop::intensity_drifted;
  return SectionStop::none;
}

}  // namespace organsmith::seg
