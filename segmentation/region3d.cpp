#include "segmentation/detail/region3d.h"

#include "segmentation/edge_map.h"
#include "segmentation/slice_ops.h"

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <deque>

namespace organsmith::seg {

double Region3d::area_mm2(std::int64_t k, double sx, double sy) const {
  if (!has(k)) return 0;
  return double(cv::countNonZero(mask[std::size_t(k - k0)])) * sx * sy;
}

Region3d grow_region3d(const Volume& vol, std::int64_t si, std::int64_t sj, std::int64_t sk,
                       const Region3dOptions& o) {
  const auto& n = vol.grid.size_vox;
  const double sx = vol.grid.spacing_mm.x(), sy = vol.grid.spacing_mm.y(), sz = vol.grid.spacing_mm.z();
  Region3d r;
  const auto hx = std::int64_t(std::ceil(o.half_width_mm / sx)), hy = std::int64_t(std::ceil(o.half_width_mm / sy));
  const auto hz = std::int64_t(std::ceil(o.half_length_mm / sz));
  r.x0 = int(std::max<std::int64_t>(0, si - hx));
  r.y0 = int(std::max<std::int64_t>(0, sj - hy));
  r.w = int(std::min<std::int64_t>(n[0] - 1, si + hx)) - r.x0 + 1;
  r.h = int(std::min<std::int64_t>(n[1] - 1, sj + hy)) - r.y0 + 1;
  r.k0 = std::max<std::int64_t>(0, sk - hz);
  r.k1 = std::min<std::int64_t>(n[2] - 1, sk + hz);
  const std::size_t K = std::size_t(r.k1 - r.k0 + 1);
  // In-window voxels, smoothed in plane only (thick slices are not mixed), and the same opened.
  std::vector<cv::Mat> in(K), core(K);
  const int rx = std::max(1, int(std::lround(o.open_mm / sx))), ry = std::max(1, int(std::lround(o.open_mm / sy)));
  const cv::Mat ball = cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * rx + 1, 2 * ry + 1});
  tbb::parallel_for(std::size_t(0), K, [&](std::size_t q) {
    const float* s = vol.slice(r.k0 + std::int64_t(q));
    std::vector<float> crop(std::size_t(r.w) * std::size_t(r.h));
    for (int y = 0; y < r.h; ++y)
      std::copy_n(s + std::size_t(r.y0 + y) * std::size_t(n[0]) + std::size_t(r.x0), r.w,
                  crop.data() + std::size_t(y) * std::size_t(r.w));
    const Image2f sm = smooth_slice(crop.data(), r.w, r.h, sx, sy, o.sigma_mm);
    cv::Mat m(r.h, r.w, CV_8U);
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w; ++x) {
        const float v = sm(x, y);
        m.at<std::uint8_t>(y, x) = v >= o.lo_hu && v <= o.hi_hu ? 255 : 0;
      }
    in[q] = m;
    cv::erode(m, core[q], ball, {-1, -1}, 1, cv::BORDER_REPLICATE);
  });
  // 3-D (6-connected) flood fill of the eroded core from the seed, or from the core voxel of the
  // seed's slice nearest to it within the opening radius.
  std::vector<cv::Mat> reach(K);
  for (auto& m : reach) m = cv::Mat::zeros(r.h, r.w, CV_8U);
  const int lx = int(si) - r.x0, ly = int(sj) - r.y0;
  const std::size_t lk = std::size_t(sk - r.k0);
  int bx = -1, by = -1;
  double bd = 1e300;
  for (int y = std::max(0, ly - ry); y <= std::min(r.h - 1, ly + ry); ++y)
    for (int x = std::max(0, lx - rx); x <= std::min(r.w - 1, lx + rx); ++x)
      if (core[lk].at<std::uint8_t>(y, x)) {
        const double d = std::hypot((x - lx) * sx, (y - ly) * sy);
        if (d < bd) bd = d, bx = x, by = y;
      }
  if (bx < 0) {
    r.k1 = r.k0 - 1;
    r.mask.clear();
    return r;
  }
  struct V {
    int x, y;
    std::size_t k;
  };
  std::deque<V> queue{{bx, by, lk}};
  reach[lk].at<std::uint8_t>(by, bx) = 255;
  while (!queue.empty()) {
    const V v = queue.front();
    queue.pop_front();
    const V nb[6] = {{v.x - 1, v.y, v.k}, {v.x + 1, v.y, v.k}, {v.x, v.y - 1, v.k},
                     {v.x, v.y + 1, v.k}, {v.x, v.y, v.k - 1}, {v.x, v.y, v.k + 1}};
    for (const V& u : nb) {
      if (u.x < 0 || u.y < 0 || u.x >= r.w || u.y >= r.h || u.k >= K) continue;  // k − 1 wraps to ≥ K
      if (!core[u.k].at<std::uint8_t>(u.y, u.x) || reach[u.k].at<std::uint8_t>(u.y, u.x)) continue;
      reach[u.k].at<std::uint8_t>(u.y, u.x) = 255;
      queue.push_back(u);
    }
  }
  // Back to full size: dilate the reached core by the same ball, within the window.
  r.mask.resize(K);
  for (std::size_t q = 0; q < K; ++q) {
    cv::Mat d;
    cv::dilate(reach[q], d, ball, {-1, -1}, 1, cv::BORDER_CONSTANT, 0);
    cv::bitwise_and(d, in[q], r.mask[q]);
  }
  // Trim empty end slices.
  while (r.k0 <= r.k1 && cv::countNonZero(r.mask.front()) == 0) r.mask.erase(r.mask.begin()), ++r.k0;
  while (r.k0 <= r.k1 && cv::countNonZero(r.mask.back()) == 0) r.mask.pop_back(), --r.k1;
  return r;
}

cv::Mat region_under(const Region3d& r, std::int64_t k, const std::vector<Point2>& contour_mm, double sx, double sy,
                     double reach_mm, int* overlap_px) {
  if (overlap_px) *overlap_px = 0;
  if (!r.has(k) || contour_mm.size() < 3) return {};
  const cv::Mat& m = r.mask[std::size_t(k - r.k0)];
  cv::Mat inside = cv::Mat::zeros(r.h, r.w, CV_8U);
  std::vector<Point2> px;
  for (const auto& p : contour_mm) px.push_back({p.x / sx - r.x0, p.y / sy - r.y0});
  rasterise(px, r.w, r.h, [&](int x, int y) { inside.at<std::uint8_t>(y, x) = 255; });
  if (reach_mm > 0) {
    const int rx = std::max(1, int(std::lround(reach_mm / sx))), ry = std::max(1, int(std::lround(reach_mm / sy)));
    cv::dilate(inside, inside, cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * rx + 1, 2 * ry + 1}));
  }
  cv::Mat labels;
  const int nl = cv::connectedComponents(m, labels, 8, CV_32S);
  std::vector<char> keep(std::size_t(std::max(nl, 1)), 0);
  int overlap = 0;
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x)
      if (inside.at<std::uint8_t>(y, x) && m.at<std::uint8_t>(y, x)) keep[std::size_t(labels.at<int>(y, x))] = 1, ++overlap;
  if (overlap_px) *overlap_px = overlap;
  if (overlap == 0) return {};
  cv::Mat out = cv::Mat::zeros(r.h, r.w, CV_8U);
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x)
      if (keep[std::size_t(labels.at<int>(y, x))] && m.at<std::uint8_t>(y, x)) out.at<std::uint8_t>(y, x) = 255;
  return out;
}

std::vector<Point2> mask_outline_mm(const Region3d& r, const cv::Mat& m, double sx, double sy) {
  return mask_outline_mm(m, r.x0 * sx, r.y0 * sy, sx, sy);
}

std::vector<Point2> mask_outline_mm(const cv::Mat& m, double x0_mm, double y0_mm, double sx, double sy) {
  std::vector<Point2> out;
  if (m.empty()) return out;
  cv::Mat padded;
  cv::copyMakeBorder(m, padded, 1, 1, 1, 1, cv::BORDER_CONSTANT, 0);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(padded, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  std::size_t best = contours.size();
  double best_area = -1;
  for (std::size_t i = 0; i < contours.size(); ++i) {
    const double a = double(contours[i].size()) + cv::contourArea(contours[i]);  // single pixels have area 0
    if (a > best_area) best_area = a, best = i;
  }
  if (best == contours.size()) return out;
  for (const cv::Point& p : contours[best]) out.push_back({x0_mm + (p.x - 1) * sx, y0_mm + (p.y - 1) * sy});
  // findContours walks clockwise in image coordinates (y down) for outer contours; the snake
  // wants counter-clockwise in (i, j) by the shoelace sign.
  if (polygon_area(out) < 0) std::reverse(out.begin(), out.end());
  return out;
}

}  // namespace organsmith::seg
