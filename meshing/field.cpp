// Scalar fields on regular grids: trilinear sampling, Gaussian smoothing, exact Euclidean
// distance transforms. Plain C++ (no CGAL), used to define the implicit organ domains.

#include "meshing/detail.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace organsmith::meshing_detail {

double Field3::sample(const Eigen::Vector3d& q) const {
  // The hot call of every implicit domain (Mesh_3 asks it millions of times per organ): no
  // clamping per corner (i0 ≤ n − 2 keeps i0 + 1 inside), one index computation.
  std::int64_t i0[3];
  double t[3];
  for (int a = 0; a < 3; ++a) {
    const double u = (q[a] - origin[a]) / h[a];
    if (!(u >= 0.0) || u > double(n[a] - 1)) return outside;
    i0[a] = std::min<std::int64_t>(std::int64_t(u), n[a] - 2);
    t[a] = u - double(i0[a]);
  }
  if (n[0] < 2 || n[1] < 2 || n[2] < 2) return double(v[std::size_t(index(i0[0] < 0 ? 0 : i0[0], i0[1] < 0 ? 0 : i0[1], i0[2] < 0 ? 0 : i0[2]))]);
  const std::int64_t sx = 1, sy = n[0], sz = n[0] * n[1];
  const float* p = v.data() + index(i0[0], i0[1], i0[2]);
  const double c00 = p[0] + t[0] * (double(p[sx]) - p[0]);
  const double c10 = p[sy] + t[0] * (double(p[sy + sx]) - p[sy]);
  const double c01 = p[sz] + t[0] * (double(p[sz + sx]) - p[sz]);
  const double c11 = p[sz + sy] + t[0] * (double(p[sz + sy + sx]) - p[sz + sy]);
  const double c0 = c00 + t[1] * (c10 - c00);
  const double c1 = c01 + t[1] * (c11 - c01);
  return c0 + t[2] * (c1 - c0);
}

namespace {

/// Runs `fn(line_start, stride, count)` over every line of the grid along `axis`.
template <class Fn>
void for_each_line(const std::array<std::int64_t, 3>& n, int axis, Fn&& fn) {
  const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
  const std::int64_t stride = axis == 0 ? 1 : axis == 1 ? n[0] : n[0] * n[1];
  tbb::parallel_for(std::int64_t(0), n[a2], [&](std::int64_t c2) {
    for (std::int64_t c1 = 0; c1 < n[a1]; ++c1) {
      std::array<std::int64_t, 3> idx{};
      idx[a1] = c1;
      idx[a2] = c2;
      idx[axis] = 0;
      fn(idx[0] + n[0] * (idx[1] + n[1] * idx[2]), stride, n[axis]);
    }
  });
}

}  // namespace

void gaussian_smooth(Field3& f, const Eigen::Vector3d& sigma) {
  for (int a = 0; a < 3; ++a) {
    if (sigma[a] <= 0.05 || f.n[a] < 2) continue;
    const int r = int(std::ceil(3.0 * sigma[a]));
    std::vector<double> w(2 * r + 1);
    double sum = 0;
    for (int d = -r; d <= r; ++d) sum += w[d + r] = std::exp(-0.5 * d * d / (sigma[a] * sigma[a]));
    for (auto& x : w) x /= sum;
    for_each_line(f.n, a, [&](std::int64_t start, std::int64_t stride, std::int64_t count) {
      std::vector<float> line(count), out(count);
      for (std::int64_t i = 0; i < count; ++i) line[i] = f.v[start + i * stride];
      for (std::int64_t i = 0; i < count; ++i) {
        double acc = 0;
        for (int d = -r; d <= r; ++d) {
          const std::int64_t j = i + d;
          acc += w[d + r] * (j < 0 || j >= count ? f.outside : line[j]);
        }
        out[i] = float(acc);
      }
      for (std::int64_t i = 0; i < count; ++i) f.v[start + i * stride] = out[i];
    });
  }
}

namespace {

/// 1-D squared distance transform (Felzenszwalb & Huttenlocher), sample spacing `h`.
void edt_line(const double* g, double* d, std::int64_t n, double h, std::vector<std::int64_t>& v,
              std::vector<double>& z) {
  const double inf = std::numeric_limits<double>::infinity();
  v.assign(n, 0);
  z.assign(n + 1, 0);
  std::int64_t k = -1;
  for (std::int64_t q = 0; q < n; ++q) {
    if (g[q] == inf) continue;
    const double pq = q * h;
    while (k >= 0) {
      const double pv = v[k] * h;
      const double s = ((g[q] + pq * pq) - (g[v[k]] + pv * pv)) / (2 * (pq - pv));
      if (s <= z[k]) { --k; continue; }
      break;
    }
    ++k;
    v[k] = q;
    z[k] = k == 0 ? -inf : ((g[q] + pq * pq) - (g[v[k - 1]] + (v[k - 1] * h) * (v[k - 1] * h))) / (2 * (pq - v[k - 1] * h));
    z[k + 1] = inf;
  }
  if (k < 0) {
    for (std::int64_t q = 0; q < n; ++q) d[q] = inf;
    return;
  }
  std::int64_t j = 0;
  for (std::int64_t q = 0; q < n; ++q) {
    while (z[j + 1] < q * h) ++j;
    const double dq = (q - v[j]) * h;
    d[q] = dq * dq + g[v[j]];
  }
}

/// Squared distance (mm²) from every sample to the nearest sample with `feature` set.
std::vector<double> squared_edt(const Field3& f, const std::vector<char>& feature) {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> d(feature.size());
  for (std::size_t i = 0; i < feature.size(); ++i) d[i] = feature[i] ? 0.0 : inf;
  for (int a = 0; a < 3; ++a) {
    for_each_line(f.n, a, [&](std::int64_t start, std::int64_t stride, std::int64_t count) {
      std::vector<double> g(count), out(count), z;
      std::vector<std::int64_t> v;
      for (std::int64_t i = 0; i < count; ++i) g[i] = d[start + i * stride];
      edt_line(g.data(), out.data(), count, f.h[a], v, z);
      for (std::int64_t i = 0; i < count; ++i) d[start + i * stride] = out[i];
    });
  }
  return d;
}

}  // namespace

Field3 signed_distance(const Field3& f, float iso, DistanceSide side) {
  std::vector<char> inside(f.v.size()), outside(f.v.size());
  for (std::size_t i = 0; i < f.v.size(); ++i) inside[i] = !(outside[i] = f.v[i] < iso);
  // One exact transform per side asked for; the other side gets ∓ half a sample (its sign).
  const bool want_in = side != DistanceSide::outside, want_out = side != DistanceSide::inside;
  const std::vector<double> to_inside = want_out ? squared_edt(f, inside) : std::vector<double>{};
  const std::vector<double> to_outside = want_in ? squared_edt(f, outside) : std::vector<double>{};
  Field3 s;
  s.n = f.n;
  s.h = f.h;
  s.origin = f.origin;
  s.v.resize(f.v.size());
  const double half = 0.5 * f.h.minCoeff();
  const double far = 1e6;
  for (std::size_t i = 0; i < f.v.size(); ++i) {
    if (inside[i])
      s.v[i] = want_in ? float(-(std::min(std::sqrt(to_outside[i]), far) - half)) : float(-half);
    else
      s.v[i] = want_out ? float(std::min(std::sqrt(to_inside[i]), far) - half) : float(half);
  }
  s.outside = float(far);
  return s;
}

Field3 resample(const Field3& f, const Box& box, double h_mm) {
  Field3 r;
  r.h = Eigen::Vector3d::Constant(h_mm);
  r.origin = box.lo;
  for (int a = 0; a < 3; ++a) r.n[a] = std::max<std::int64_t>(2, std::int64_t(std::ceil((box.hi[a] - box.lo[a]) / h_mm)) + 1);
  r.outside = f.outside;
  r.v.resize(std::size_t(r.n[0] * r.n[1] * r.n[2]));
  tbb::parallel_for(std::int64_t(0), r.n[2], [&](std::int64_t k) {
    for (std::int64_t j = 0; j < r.n[1]; ++j)
      for (std::int64_t i = 0; i < r.n[0]; ++i)
        r.v[std::size_t(r.index(i, j, k))] =
            float(f.sample(r.origin + Eigen::Vector3d(double(i), double(j), double(k)) * h_mm));
  });
  return r;
}

}  // namespace organsmith::meshing_detail
