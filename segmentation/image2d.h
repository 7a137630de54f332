#pragma once
// A single-channel float image of one slice (x = column i, y = row j, x fastest). Plain C++ with
// no Eigen or third-party types, so that the ITK reference code can share it.

#include <cstddef>
#include <vector>

namespace organsmith::seg {

struct Image2f {
  int width = 0;
  int height = 0;
  std::vector<float> px;  ///< width × height values, row-major (x fastest)

  Image2f() = default;
  Image2f(int w, int h, float value = 0.0f) : width(w), height(h), px(std::size_t(w) * std::size_t(h), value) {}
  void reset(int w, int h) {
    width = w;
    height = h;
    px.resize(std::size_t(w) * std::size_t(h));
  }
  float& operator()(int x, int y) { return px[std::size_t(y) * std::size_t(width) + std::size_t(x)]; }
  float operator()(int x, int y) const { return px[std::size_t(y) * std::size_t(width) + std::size_t(x)]; }
  float* row(int y) { return px.data() + std::size_t(y) * std::size_t(width); }
  const float* row(int y) const { return px.data() + std::size_t(y) * std::size_t(width); }
  bool empty() const { return px.empty(); }
  /// Bilinear sample at continuous pixel coordinates, clamped to the image.
  float sample(double x, double y) const;
};

inline float Image2f::sample(double x, double y) const {
  if (x < 0) x = 0;
  if (y < 0) y = 0;
  if (x > width - 1) x = width - 1;
  if (y > height - 1) y = height - 1;
  const int x0 = int(x), y0 = int(y);
  const int x1 = x0 + 1 < width ? x0 + 1 : x0, y1 = y0 + 1 < height ? y0 + 1 : y0;
  const float fx = float(x - x0), fy = float(y - y0);
  const float a = (*this)(x0, y0) * (1 - fx) + (*this)(x1, y0) * fx;
  const float b = (*this)(x0, y1) * (1 - fx) + (*this)(x1, y1) * fx;
  return a * (1 - fy) + b * fy;
}

}  // namespace organsmith::seg
