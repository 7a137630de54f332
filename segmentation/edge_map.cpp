#include "segmentation/edge_map.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>

namespace organsmith::seg {

namespace {

void gaussian(cv::Mat& m, double spacing_x_mm, double spacing_y_mm, double sigma_mm) {
  if (sigma_mm <= 0) return;
  const double sx = sigma_mm / spacing_x_mm, sy = sigma_mm / spacing_y_mm;
  // Kernel radius 3σ (odd size) so the result does not depend on OpenCV's size heuristics.
  const int kx = 2 * int(std::ceil(3 * sx)) + 1, ky = 2 * int(std::ceil(3 * sy)) + 1;
  cv::GaussianBlur(m, m, cv::Size(kx, ky), sx, sy, cv::BORDER_REPLICATE);
}

}  // namespace

Image2f smooth_slice(const float* hu, int width, int height, double spacing_x_mm, double spacing_y_mm,
                     double sigma_mm) {
  Image2f out(width, height);
  cv::Mat src(height, width, CV_32F, const_cast<float*>(hu));
  cv::Mat dst(height, width, CV_32F, out.px.data());
  src.copyTo(dst);
  gaussian(dst, spacing_x_mm, spacing_y_mm, sigma_mm);
  return out;
}

Image2f edge_map(const float* hu, int width, int height, double spacing_x_mm, double spacing_y_mm,
                 const EdgeMapOptions& options) {
  const float lo = float(options.window_lo_hu), hi = float(options.window_hi_hu);
  const float scale = hi > lo ? 1.0f / (hi - lo) : 1.0f;
  cv::Mat w(height, width, CV_32F);
  for (int y = 0; y < height; ++y) {
    const float* s = hu + std::size_t(y) * width;
    float* d = w.ptr<float>(y);
    for (int x = 0; x < width; ++x) d[x] = (std::clamp(s[x], lo, hi) - lo) * scale;
  }
  gaussian(w, spacing_x_mm, spacing_y_mm, options.sigma_mm);
  Image2f f(width, height);
  float fmax = 0.0f;
  for (int y = 0; y < height; ++y) {
    const float* r = w.ptr<float>(y);
    const float* up = w.ptr<float>(std::max(y - 1, 0));
    const float* dn = w.ptr<float>(std::min(y + 1, height - 1));
    const float hy = (y == 0 || y == height - 1) ? 1.0f : 0.5f;
    float* o = f.row(y);
    for (int x = 0; x < width; ++x) {
      const int xl = std::max(x - 1, 0), xr = std::min(x + 1, width - 1);
      const float gx = (r[xr] - r[xl]) / float(xr - xl > 0 ? xr - xl : 1);
      const float gy = (dn[x] - up[x]) * hy;
      o[x] = gx * gx + gy * gy;
      fmax = std::max(fmax, o[x]);
    }
  }
  if (fmax > 0)
    for (float& v : f.px) v /= fmax;
  return f;
}

}  // namespace organsmith::seg
