#include "segmentation/detail/grid3d.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace organsmith::seg::detail {
namespace {

/// One-dimensional squared distance transform of `f` along a line of n samples spaced h apart.
void edt_line(const float* f, float* d, int n, double h, std::vector<int>& v, std::vector<double>& z) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  int k = -1;
  v.resize(std::size_t(n));
  z.resize(std::size_t(n) + 1);
  for (int q = 0; q < n; ++q) {
    if (!std::isfinite(f[q])) continue;
    const double fq = f[q], xq = q * h;
    while (k >= 0) {
      const double xv = v[std::size_t(k)] * h;
      const double s = ((fq + xq * xq) - (double(f[v[std::size_t(k)]]) + xv * xv)) / (2 * (xq - xv));
      if (s <= z[std::size_t(k)]) {
        --k;
      } else {
        ++k;
        v[std::size_t(k)] = q;
        z[std::size_t(k)] = s;
        z[std::size_t(k) + 1] = inf;
        break;
      }
    }
    if (k < 0) {
      k = 0;
      v[0] = q;
      z[0] = -inf;
      z[1] = inf;
    }
  }
  if (k < 0) {
    std::fill(d, d + n, std::numeric_limits<float>::infinity());
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[std::size_t(j) + 1] < q * h) ++j;
    const double dx = (q - v[std::size_t(j)]) * h;
    d[q] = float(dx * dx + f[v[std::size_t(j)]]);
  }
}

/// Running sums of window half-width rr along `len` elements spaced `es` apart, for `count` lines
/// whose first elements are `ls` apart (`run`: count accumulators). The lines advance together so
/// that their independent sums overlap (and vectorise where ls = 1); each line's additions are in
/// the same order as one line's alone.
void running_sums(const float* cur, float* nxt, std::size_t count, std::size_t ls, std::size_t es, int len, int rr,
                  double* run) {
  for (std::size_t i = 0; i < count; ++i) run[i] = 0;
  for (int q = 0; q <= std::min(rr, len - 1); ++q)
    for (std::size_t i = 0; i < count; ++i) run[i] += cur[i * ls + std::size_t(q) * es];
  for (int p = 0; p < len; ++p) {
    float* out = nxt + std::size_t(p) * es;
    for (std::size_t i = 0; i < count; ++i) out[i * ls] = float(run[i]);
    const int add = p + rr + 1, drop = p - rr;
    if (add < len) {
      const float* in = cur + std::size_t(add) * es;
      for (std::size_t i = 0; i < count; ++i) run[i] += in[i * ls];
    }
    if (drop >= 0) {
      const float* in = cur + std::size_t(drop) * es;
      for (std::size_t i = 0; i < count; ++i) run[i] -= in[i * ls];
    }
  }
}

}  // namespace

/// Separable Gaussian of σ mm along each axis whose σ is at least half a voxel (zero-flux borders).
void gaussian(std::vector<float>& a, const Box& b, double sigma_mm) {
  const std::array<double, 3> h{b.hx, b.hy, b.hz};
  const std::array<int, 3> n{b.nx, b.ny, b.nz};
  const std::array<std::size_t, 3> stride{1, std::size_t(b.nx), std::size_t(b.nx) * b.ny};
  for (int ax = 0; ax < 3; ++ax) {
    const double s = sigma_mm / h[std::size_t(ax)];
    if (s < 0.5 || n[std::size_t(ax)] < 2) continue;
    const int r = int(std::ceil(3 * s));
    std::vector<double> w(std::size_t(2 * r + 1));
    double sum = 0;
    for (int t = -r; t <= r; ++t) sum += w[std::size_t(t + r)] = std::exp(-0.5 * t * t / (s * s));
    for (auto& x : w) x /= sum;
    const int len = n[std::size_t(ax)];
    const std::size_t st = stride[std::size_t(ax)];
    const std::size_t lines = a.size() / std::size_t(len);
    std::vector<float> out(a.size());
    tbb::parallel_for(std::size_t(0), lines, [&](std::size_t l) {
      // line l: its first element
      const std::size_t base = line_start(ax, l, b.nx, b.ny, len);
      for (int p = 0; p < len; ++p) {
        double acc = 0;
        for (int t = -r; t <= r; ++t) acc += w[std::size_t(t + r)] * a[base + std::size_t(std::clamp(p + t, 0, len - 1)) * st];
        out[base + std::size_t(p) * st] = float(acc);
      }
    });
    a.swap(out);
  }
}

/// Sums of `cur` over the (2rx+1)(2ry+1)(2rz+1) window around every voxel, truncated at the box's
/// faces (running sums along each axis), in place; `nxt` is scratch of the same size (kept by the
/// caller: fresh arrays of a few MB each call cost more in page faults than the sums).
void box_sum(std::vector<float>& cur, std::vector<float>& nxt, const Box& b, int rx, int ry, int rz) {
  const std::size_t NX = std::size_t(b.nx), NXY = NX * std::size_t(b.ny);
  if (rx > 0 && b.nx >= 2) {  // x: a slice's rows together
    tbb::parallel_for(0, b.nz, [&](int z) {
      std::vector<double> run(std::size_t(b.ny));
      running_sums(cur.data() + z * NXY, nxt.data() + z * NXY, std::size_t(b.ny), NX, 1, b.nx, rx, run.data());
    });
    cur.swap(nxt);
  }
  if (ry > 0 && b.ny >= 2) {  // y: a slice's columns together
    tbb::parallel_for(0, b.nz, [&](int z) {
      std::vector<double> run(NX);
      running_sums(cur.data() + z * NXY, nxt.data() + z * NXY, NX, 1, NX, b.ny, ry, run.data());
    });
    cur.swap(nxt);
  }
  if (rz > 0 && b.nz >= 2) {  // z: blocks of a slice's voxels together
    const std::size_t block = 512;
    tbb::parallel_for(std::size_t(0), (NXY + block - 1) / block, [&](std::size_t c) {
      const std::size_t first = c * block, count = std::min(block, NXY - first);
      std::vector<double> run(count);
      running_sums(cur.data() + first, nxt.data() + first, count, 1, NXY, b.nz, rz, run.data());
    });
    cur.swap(nxt);
  }
}


/// Central differences in mm (one-sided at the box's faces).
Grad central(const std::vector<float>& a, const Box& b, int x, int y, int z) {
  auto d = [&](int lo, int hi, int p, double h, auto idx) {
    const int m = std::max(p - 1, 0), q = std::min(p + 1, hi);
    if (q == m) return 0.0;
    (void)lo;
    return (double(a[idx(q)]) - double(a[idx(m)])) / ((q - m) * h);
  };
  return {d(0, b.nx - 1, x, b.hx, [&](int v) { return b.at(v, y, z); }),
          d(0, b.ny - 1, y, b.hy, [&](int v) { return b.at(x, v, z); }),
          d(0, b.nz - 1, z, b.hz, [&](int v) { return b.at(x, y, v); })};
}

/// Connected (6-neighbour) part of `in` that touches `seed`, with enclosed background filled.
std::vector<std::uint8_t> simple_topology(const std::vector<std::uint8_t>& in, const std::vector<std::uint8_t>& seed,
                                          const Box& b) {
  const std::size_t n = b.size();
  std::vector<std::uint8_t> out(n, 0);
  std::vector<std::size_t> stack;
  auto push_nb = [&](std::size_t p, auto&& ok, std::vector<std::uint8_t>& mark) {
    const int x = int(p % b.nx), y = int((p / b.nx) % b.ny), z = int(p / (std::size_t(b.nx) * b.ny));
    const int dx[6] = {-1, 1, 0, 0, 0, 0}, dy[6] = {0, 0, -1, 1, 0, 0}, dz[6] = {0, 0, 0, 0, -1, 1};
    for (int e = 0; e < 6; ++e) {
      const int X = x + dx[e], Y = y + dy[e], Z = z + dz[e];
      if (X < 0 || Y < 0 || Z < 0 || X >= b.nx || Y >= b.ny || Z >= b.nz) continue;
      const std::size_t q = b.at(X, Y, Z);
      if (!mark[q] && ok(q)) mark[q] = 1, stack.push_back(q);
    }
  };
  for (std::size_t p = 0; p < n; ++p)
    if (seed[p] && in[p] && !out[p]) out[p] = 1, stack.push_back(p);
  while (!stack.empty()) {
    const std::size_t p = stack.back();
    stack.pop_back();
    push_nb(p, [&](std::size_t q) { return in[q] != 0; }, out);
  }
  // Background reachable from the box's faces stays background; the rest is a cavity.
  std::vector<std::uint8_t> outside(n, 0);
  for (int z = 0; z < b.nz; ++z)
    for (int y = 0; y < b.ny; ++y)
      for (int x = 0; x < b.nx; ++x) {
        if (x > 0 && y > 0 && z > 0 && x < b.nx - 1 && y < b.ny - 1 && z < b.nz - 1) continue;
        const std::size_t p = b.at(x, y, z);
        if (!out[p] && !outside[p]) outside[p] = 1, stack.push_back(p);
      }
  while (!stack.empty()) {
    const std::size_t p = stack.back();
    stack.pop_back();
    push_nb(p, [&](std::size_t q) { return out[q] == 0; }, outside);
  }
  for (std::size_t p = 0; p < n; ++p) out[p] = !outside[p];
  // No hole through a slice either: each slice's background not reachable in-plane from the
  // slice's border joins (a section is a filled outline).
  std::vector<std::uint8_t> reach(std::size_t(b.nx) * b.ny);
  std::vector<std::size_t> st2;
  for (int z = 0; z < b.nz; ++z) {
    std::fill(reach.begin(), reach.end(), 0);
    auto at2 = [&](int x, int y) { return std::size_t(y) * b.nx + x; };
    for (int y = 0; y < b.ny; ++y)
      for (int x = 0; x < b.nx; ++x)
        if ((x == 0 || y == 0 || x == b.nx - 1 || y == b.ny - 1) && !out[b.at(x, y, z)]) reach[at2(x, y)] = 1, st2.push_back(at2(x, y));
    while (!st2.empty()) {
      const std::size_t p = st2.back();
      st2.pop_back();
      const int x = int(p % b.nx), y = int(p / b.nx);
      const int dx[4] = {-1, 1, 0, 0}, dy[4] = {0, 0, -1, 1};
      for (int e = 0; e < 4; ++e) {
        const int X = x + dx[e], Y = y + dy[e];
        if (X < 0 || Y < 0 || X >= b.nx || Y >= b.ny) continue;
        const std::size_t q = at2(X, Y);
        if (!reach[q] && !out[b.at(X, Y, z)]) reach[q] = 1, st2.push_back(q);
      }
    }
    for (int y = 0; y < b.ny; ++y)
      for (int x = 0; x < b.nx; ++x)
        if (!reach[at2(x, y)]) out[b.at(x, y, z)] = 1;
  }
  return out;
}

std::vector<float> distance_sq_mm2(const std::vector<std::uint8_t>& feature, int nx, int ny, int nz, double hx,
                                   double hy, double hz) {
  const std::size_t n = std::size_t(nx) * ny * nz;
  std::vector<float> d(n);
  for (std::size_t p = 0; p < n; ++p) d[p] = feature[p] ? 0.f : std::numeric_limits<float>::infinity();
  const int dims[3] = {nx, ny, nz};
  const double hs[3] = {hx, hy, hz};
  const std::size_t stride[3] = {1, std::size_t(nx), std::size_t(nx) * ny};
  for (int ax = 0; ax < 3; ++ax) {
    const int len = dims[ax];
    const std::size_t lines = n / std::size_t(len);
    tbb::parallel_for(std::size_t(0), lines, [&](std::size_t l) {
      const std::size_t base = line_start(ax, l, nx, ny, len);
      std::vector<float> f(static_cast<std::size_t>(len)), o(static_cast<std::size_t>(len));
      std::vector<int> v;
      std::vector<double> z;
      for (int p = 0; p < len; ++p) f[std::size_t(p)] = d[base + std::size_t(p) * stride[ax]];
      edt_line(f.data(), o.data(), len, hs[ax], v, z);
      for (int p = 0; p < len; ++p) d[base + std::size_t(p) * stride[ax]] = o[std::size_t(p)];
    });
  }
  return d;
}

}  // namespace organsmith::seg::detail
