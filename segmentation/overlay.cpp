#include "segmentation/segment.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace organsmith {

namespace {

// Slice k as 8-bit grey, window [lo, hi] HU, rows = j, columns = i (the radiological display
// of an LPS-oriented axial slice: patient's right on the image's left, anterior at the top).
cv::Mat grey_slice(const Volume& v, std::int64_t k, double lo, double hi) {
  const int W = int(v.grid.size_vox[0]), H = int(v.grid.size_vox[1]);
  cv::Mat m(H, W, CV_8U);
  const float* s = v.slice(k);
  const double sc = 255.0 / std::max(hi - lo, 1.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      m.at<std::uint8_t>(y, x) = cv::saturate_cast<std::uint8_t>((s[std::size_t(y) * W + x] - lo) * sc);
  cv::Mat rgb;
  cv::cvtColor(m, rgb, cv::COLOR_GRAY2BGR);
  return rgb;
}

std::vector<cv::Point2d> contour_px(const Volume& v, const Contour& c) {
  std::vector<cv::Point2d> px;
  for (const auto& p : c.points_lps_mm) {
    const Eigen::Vector3d ijk = v.grid.lps_mm_to_index(p);
    px.push_back({ijk.x(), ijk.y()});
  }
  return px;
}

void draw(cv::Mat& img, const std::vector<cv::Point2d>& px, double scale, cv::Point2d off, const cv::Scalar& colour) {
  // Sub-pixel polyline (4 fractional bits).
  std::vector<cv::Point> q;
  for (const auto& p : px) q.push_back({int(std::lround(((p.x - off.x) * scale + scale / 2) * 16)),
                                        int(std::lround(((p.y - off.y) * scale + scale / 2) * 16))});
  const cv::Point* pts = q.data();
  const int n = int(q.size());
  cv::polylines(img, &pts, &n, 1, true, colour, 1, cv::LINE_AA, 4);
}

void write_png(const std::filesystem::path& path, const cv::Mat& img) {
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), img);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) throw OutputError("cannot write the overlay image", path, "check that the directory is writable");
}

}  // namespace

void write_overlays(const Volume& v, const SegmentationResult& r, const std::filesystem::path& dir,
                    const OverlayOptions& o) {
  const cv::Scalar colours[] = {{0, 0, 255}, {255, 200, 0}, {0, 255, 0}, {255, 0, 255}};
  for (std::size_t oi = 0; oi < r.organs.size(); ++oi) {
    const OrganSegmentation& org = r.organs[oi];
    const auto& cs = org.contours.contours;
    if (cs.empty()) continue;
    const cv::Scalar col = colours[oi % 4];
    // Tile centre: the organ's mean position in the slice plane over all contours.
    double cx = 0, cy = 0;
    std::size_t n = 0;
    for (const auto& c : cs)
      for (const auto& p : contour_px(v, c)) cx += p.x, cy += p.y, ++n;
    cx /= double(n);
    cy /= double(n);
    const int tiles = std::min<int>(o.max_tiles, int(cs.size()));
    const int cols = int(std::ceil(std::sqrt(double(tiles))));
    const int rows = (tiles + cols - 1) / cols;
    cv::Mat montage(rows * o.tile_px, cols * o.tile_px, CV_8UC3, cv::Scalar(0, 0, 0));
    const double half_px = o.tile_mm / 2.0 / v.grid.spacing_mm.x();
    const double scale = o.tile_px / (2 * half_px);
    for (int t = 0; t < tiles; ++t) {
      const std::size_t ci = tiles == 1 ? 0 : std::size_t(std::lround(double(t) * double(cs.size() - 1) / (tiles - 1)));
      const Contour& c = cs[ci];
      cv::Mat grey = grey_slice(v, c.slice_k, o.window_lo_hu, o.window_hi_hu);
      const cv::Point2d off{cx - half_px, cy - half_px};
      cv::Mat tile(o.tile_px, o.tile_px, CV_8UC3);
      cv::Mat M = (cv::Mat_<double>(2, 3) << scale, 0, -off.x * scale, 0, scale, -off.y * scale);
      cv::warpAffine(grey, tile, M, tile.size(), cv::INTER_NEAREST, cv::BORDER_CONSTANT, cv::Scalar(0, 0, 0));
      draw(tile, contour_px(v, c), scale, off, col);
      cv::putText(tile, "k=" + std::to_string(c.slice_k), {4, 14}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {255, 255, 255}, 1,
                  cv::LINE_AA);
      tile.copyTo(montage(cv::Rect((t % cols) * o.tile_px, (t / cols) * o.tile_px, o.tile_px, o.tile_px)));
    }
    write_png(dir / ("overlay_" + org.organ + ".png"), montage);
    // The whole middle slice, for context.
    const Contour& mid = cs[cs.size() / 2];
    cv::Mat full = grey_slice(v, mid.slice_k, o.window_lo_hu, o.window_hi_hu);
    draw(full, contour_px(v, mid), 1.0, {0, 0}, col);
    cv::putText(full, org.organ + " k=" + std::to_string(mid.slice_k), {6, 18}, cv::FONT_HERSHEY_SIMPLEX, 0.5,
                {255, 255, 255}, 1, cv::LINE_AA);
    write_png(dir / ("overlay_" + org.organ + "_full.png"), full);
  }
}

}  // namespace organsmith
