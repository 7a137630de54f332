#pragma once
// Small raster helpers shared by the segmentation sources (internal; not installed).

#include "segmentation/image2d.h"
#include "segmentation/snake.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace organsmith::seg {

/// Calls fn(x, y) for every pixel whose centre lies inside the polygon `pts_px` (pixel
/// coordinates), clipped to [0, w) × [0, h). Even–odd rule; the polygon is simple.
template <typename Fn>
void rasterise(const std::vector<Point2>& pts_px, int w, int h, Fn&& fn) {
  if (pts_px.size() < 3) return;
  double ymin = pts_px[0].y, ymax = ymin;
  for (const auto& p : pts_px) ymin = std::min(ymin, p.y), ymax = std::max(ymax, p.y);
  const int y0 = std::max(0, int(std::ceil(ymin))), y1 = std::min(h - 1, int(std::floor(ymax)));
  std::vector<double> xs;
  const std::size_t n = pts_px.size();
  for (int y = y0; y <= y1; ++y) {
    xs.clear();
    for (std::size_t i = 0; i < n; ++i) {
      const Point2& a = pts_px[i];
      const Point2& b = pts_px[(i + 1) % n];
      if ((a.y <= y && y < b.y) || (b.y <= y && y < a.y)) xs.push_back(a.x + (y - a.y) * (b.x - a.x) / (b.y - a.y));
    }
    std::sort(xs.begin(), xs.end());
    for (std::size_t i = 0; i + 1 < xs.size(); i += 2) {
      const int xa = std::max(0, int(std::ceil(xs[i]))), xb = std::min(w - 1, int(std::ceil(xs[i + 1])) - 1);
      for (int x = xa; x <= xb; ++x) fn(x, y);
    }
  }
}

}  // namespace organsmith::seg
