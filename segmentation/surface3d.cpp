// Over 400 lines: the surface's evolution and the grid tools only it uses (exact anisotropic
// distance transform, separable Gaussian, running-sum box filter, topology clean-up) share the
// working box and its indexing; split out, the tools would be a header of private helpers.
#include "segmentation/surface3d.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

namespace organsmith::seg {
namespace {

/// The working box: a sub-grid of the volume, x fastest.
struct Box {
  std::int64_t i0 = 0, j0 = 0, k0 = 0;
  int nx = 0, ny = 0, nz = 0;
  double hx = 1, hy = 1, hz = 1;
  std::size_t size() const { return std::size_t(nx) * ny * nz; }
  std::size_t at(int x, int y, int z) const { return (std::size_t(z) * ny + y) * nx + x; }
};

/// First element of line l along axis ax (0 = x, 1 = y, 2 = z) of an nx × ny × … grid, x fastest;
/// len is the line's length.
std::size_t line_start(int ax, std::size_t l, int nx, int ny, int len) {
  if (ax == 0) return l * std::size_t(len);
  if (ax == 1) return (l / std::size_t(nx)) * std::size_t(nx) * std::size_t(ny) + (l % std::size_t(nx));
  return l;
}

template <class F>
void for_slices(const Box& b, bool parallel, F&& f) {
  if (parallel)
    tbb::parallel_for(0, b.nz, [&](int z) { f(z); });
  else
    for (int z = 0; z < b.nz; ++z) f(z);
}

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

/// Sums of `a` over the (2rx+1)(2ry+1)(2rz+1) window around every voxel, truncated at the box's
/// faces (running sums along each axis).
std::vector<float> box_sum(const std::vector<float>& a, const Box& b, int rx, int ry, int rz) {
  std::vector<float> cur = a, nxt(a.size());
  const int n[3] = {b.nx, b.ny, b.nz}, r[3] = {rx, ry, rz};
  const std::size_t stride[3] = {1, std::size_t(b.nx), std::size_t(b.nx) * b.ny};
  for (int ax = 0; ax < 3; ++ax) {
    const int len = n[ax], rr = r[ax];
    if (rr <= 0 || len < 2) continue;
    const std::size_t lines = a.size() / std::size_t(len);
    tbb::parallel_for(std::size_t(0), lines, [&](std::size_t l) {
      const std::size_t base = line_start(ax, l, b.nx, b.ny, len);
      double run = 0;
      for (int q = 0; q <= std::min(rr, len - 1); ++q) run += cur[base + std::size_t(q) * stride[ax]];
      for (int p = 0; p < len; ++p) {
        nxt[base + std::size_t(p) * stride[ax]] = float(run);
        const int add = p + rr + 1, drop = p - rr;
        if (add < len) run += cur[base + std::size_t(add) * stride[ax]];
        if (drop >= 0) run -= cur[base + std::size_t(drop) * stride[ax]];
      }
    });
    cur.swap(nxt);
  }
  return cur;
}

struct Grad {
  double x, y, z;
};

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

}  // namespace

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

Surface3dResult evolve_surface3d(const Volume& vol, const std::vector<std::uint8_t>& start,
                                 const Surface3dOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  Surface3dResult res;
  const auto& g = vol.grid;
  const std::int64_t NX = g.size_vox[0], NY = g.size_vox[1], NZ = g.size_vox[2];
  res.mask.assign(std::size_t(g.voxel_count()), 0);
  // The start's box, grown by the margin.
  std::int64_t lo[3] = {NX, NY, NZ}, hi[3] = {-1, -1, -1};
  for (std::int64_t k = 0; k < NZ; ++k)
    for (std::int64_t j = 0; j < NY; ++j)
      for (std::int64_t i = 0; i < NX; ++i)
        if (start[std::size_t(g.offset(i, j, k))]) {
          lo[0] = std::min(lo[0], i), hi[0] = std::max(hi[0], i);
          lo[1] = std::min(lo[1], j), hi[1] = std::max(hi[1], j);
          lo[2] = std::min(lo[2], k), hi[2] = std::max(hi[2], k);
          ++res.start_voxels;
        }
  if (res.start_voxels == 0) return res;
  Box b;
  b.hx = g.spacing_mm.x(), b.hy = g.spacing_mm.y(), b.hz = g.spacing_mm.z();
  const double h[3] = {b.hx, b.hy, b.hz};
  const std::int64_t N[3] = {NX, NY, NZ};
  std::int64_t b0[3], b1[3];
  for (int a = 0; a < 3; ++a) {
    std::int64_t m = std::int64_t(std::ceil(o.margin_mm / h[a]));
    if (a == 2) m = std::max<std::int64_t>(m, 2);
    b0[a] = std::max<std::int64_t>(0, lo[a] - m);
    b1[a] = std::min<std::int64_t>(N[a] - 1, hi[a] + m);
  }
  b.i0 = b0[0], b.j0 = b0[1], b.k0 = b0[2];
  b.nx = int(b1[0] - b0[0] + 1), b.ny = int(b1[1] - b0[1] + 1), b.nz = int(b1[2] - b0[2] + 1);
  const std::size_t n = b.size();
  std::vector<float> hu(n);
  std::vector<std::uint8_t> s0(n);
  for (int z = 0; z < b.nz; ++z)
    for (int y = 0; y < b.ny; ++y)
      for (int x = 0; x < b.nx; ++x) {
        const std::int64_t off = g.offset(b.i0 + x, b.j0 + y, b.k0 + z);
        hu[b.at(x, y, z)] = vol.hu[std::size_t(off)];
        s0[b.at(x, y, z)] = start[std::size_t(off)] ? 1 : 0;
      }

  // Region speed on the smoothed HU.
  std::vector<float> sm = hu;
  gaussian(sm, b, o.region_sigma_mm);
  // The window bounds growth at half-way to the tissue beyond it (the organ's window is set a
  // third of the way, so that the slices' snake does not leak; half-way is where a blurred wall's
  // boundary lies, as in the slices' seating).
  const double mid = 0.5 * (o.lo_hu + o.hi_hu);
  const double lo_veto = mid - o.veto_widen * (mid - o.lo_hu), hi_veto = mid + o.veto_widen * (o.hi_hu - mid);
  std::vector<float> R(n);
  for (std::size_t p = 0; p < n; ++p)
    R[p] = float(std::clamp(std::min(sm[p] - lo_veto, hi_veto - sm[p]) / std::max(o.ramp_hu, 1e-6), -1.0, 1.0));

  // Edge stop of the outward push: g = 1 / (1 + (|∇I_σ| / k)²) on the HU smoothed like the edge
  // map, k in HU/mm (a wall's step of ~50–100 HU over its blur of a few mm is 15–30 HU/mm: g ≈
  // 0.1–0.3 at k = 10; noise left after smoothing is a few HU/mm: g ≈ 1 inside the organ).
  if (o.edge_stop_hu_per_mm > 0) {
    std::vector<float> es = hu;
    gaussian(es, b, o.edge_sigma_mm);
    for (int z = 0; z < b.nz; ++z)
      for (int y = 0; y < b.ny; ++y)
        for (int x = 0; x < b.nx; ++x) {
          const Grad gr = central(es, b, x, y, z);
          const double q = (gr.x * gr.x + gr.y * gr.y) / (o.edge_stop_hu_per_mm * o.edge_stop_hu_per_mm);
          float& r = R[b.at(x, y, z)];
          if (r > 0) r = float(r / (1 + q));
        }
  }

  // Edge map and its GVF, in mm.
  std::vector<float> f(n);
  for (std::size_t p = 0; p < n; ++p)
    f[p] = float(std::clamp((hu[p] - o.edge_lo_hu) / (o.edge_hi_hu - o.edge_lo_hu), 0.0, 1.0));
  gaussian(f, b, o.edge_sigma_mm);
  {
    std::vector<float> e(n);
    double fmax = 0;
    for (int z = 0; z < b.nz; ++z)
      for (int y = 0; y < b.ny; ++y)
        for (int x = 0; x < b.nx; ++x) {
          const Grad gr = central(f, b, x, y, z);
          e[b.at(x, y, z)] = float(gr.x * gr.x + gr.y * gr.y + gr.z * gr.z);
          fmax = std::max(fmax, double(e[b.at(x, y, z)]));
        }
    if (fmax > 0)
      for (auto& v : e) v = float(v / fmax);
    f.swap(e);
  }
  std::vector<float> fx(n), fy(n), fz(n), bb(n);
  double bmax = 0;
  for (int z = 0; z < b.nz; ++z)
    for (int y = 0; y < b.ny; ++y)
      for (int x = 0; x < b.nx; ++x) {
        const Grad gr = central(f, b, x, y, z);
        const std::size_t p = b.at(x, y, z);
        fx[p] = float(gr.x), fy[p] = float(gr.y), fz[p] = float(gr.z);
        bb[p] = float(gr.x * gr.x + gr.y * gr.y + gr.z * gr.z);
        bmax = std::max(bmax, double(bb[p]));
      }
  std::vector<float> u = fx, v = fy, w = fz;
  {
    const double mu = o.gvf_mu * b.hx * b.hy;  // pixel units → mm²
    const double lap = 2 * mu * (1 / (b.hx * b.hx) + 1 / (b.hy * b.hy) + (b.nz > 1 ? 1 / (b.hz * b.hz) : 0));
    const double dt = 1 / (lap + bmax + 1e-12);
    std::vector<float> u2(n), v2(n), w2(n);
    for (int it = 0; it < o.gvf_iterations; ++it) {
      for_slices(b, o.parallel, [&](int z) {
        const int zm = std::max(z - 1, 0), zp = std::min(z + 1, b.nz - 1);
        for (int y = 0; y < b.ny; ++y) {
          const int ym = std::max(y - 1, 0), yp = std::min(y + 1, b.ny - 1);
          for (int x = 0; x < b.nx; ++x) {
            const int xm = std::max(x - 1, 0), xp = std::min(x + 1, b.nx - 1);
            const std::size_t p = b.at(x, y, z);
            auto step = [&](const std::vector<float>& a, const std::vector<float>& d) {
              const double L = (a[b.at(xm, y, z)] + a[b.at(xp, y, z)] - 2.0 * a[p]) / (b.hx * b.hx) +
                               (a[b.at(x, ym, z)] + a[b.at(x, yp, z)] - 2.0 * a[p]) / (b.hy * b.hy) +
                               (a[b.at(x, y, zm)] + a[b.at(x, y, zp)] - 2.0 * a[p]) / (b.hz * b.hz);
              return float(a[p] + dt * (mu * L - bb[p] * (a[p] - d[p])));
            };
            u2[p] = step(u, fx), v2[p] = step(v, fy), w2[p] = step(w, fz);
          }
        }
      });
      u.swap(u2), v.swap(v2), w.swap(w2);
    }
    double vmax = 0;
    for (std::size_t p = 0; p < n; ++p) vmax = std::max(vmax, double(u[p]) * u[p] + double(v[p]) * v[p] + double(w[p]) * w[p]);
    vmax = std::sqrt(vmax);
    if (vmax > 0)
      for (std::size_t p = 0; p < n; ++p) u[p] = float(u[p] / vmax), v[p] = float(v[p] / vmax), w[p] = float(w[p] / vmax);
  }

  // Level set: signed distance to the start's boundary, and the distance to the start itself.
  std::vector<std::uint8_t> outside0(n);
  for (std::size_t p = 0; p < n; ++p) outside0[p] = !s0[p];
  const std::vector<float> din = distance_sq_mm2(s0, b.nx, b.ny, b.nz, b.hx, b.hy, b.hz);
  const std::vector<float> dout = distance_sq_mm2(outside0, b.nx, b.ny, b.nz, b.hx, b.hy, b.hz);
  std::vector<float> phi(n), limit(n);
  for (std::size_t p = 0; p < n; ++p) {
    const double di = std::sqrt(double(din[p])), dou = std::isfinite(dout[p]) ? std::sqrt(double(dout[p])) : 1e3;
    // Half the distance across the boundary on each side: the zero lies half-way between a
    // voxel inside and its neighbour outside, with a unit slope along the axis of contact.
    phi[p] = float(s0[p] ? -0.5 * dou : 0.5 * di);
    limit[p] = float(di - o.max_grow_mm);  // φ may not fall below this (points too far stay out)
  }
  // What stays inside whatever the image says: the start, or the start opened by a ball.
  std::vector<std::uint8_t> core = s0;
  if (o.open_start_mm > 0) {
    // The start opened by a ball: its parts narrower than the ball (a lobe taken in through a gap,
    // a bridge) must be won again by the surface; the rest stays.
    std::vector<std::uint8_t> eroded(n);
    const double r2 = o.open_start_mm * o.open_start_mm;
    for (std::size_t p = 0; p < n; ++p) eroded[p] = s0[p] && (!std::isfinite(dout[p]) || dout[p] > r2);
    const std::vector<float> de = distance_sq_mm2(eroded, b.nx, b.ny, b.nz, b.hx, b.hy, b.hz);
    for (std::size_t p = 0; p < n; ++p) core[p] = core[p] && de[p] <= r2;
  }
  const double hmin = std::min({b.hx, b.hy, b.nz > 1 ? b.hz : b.hx});
  const double inv2 = 1 / (b.hx * b.hx) + 1 / (b.hy * b.hy) + (b.nz > 1 ? 1 / (b.hz * b.hz) : 0);  // (hzc ≥ hz)
  // Curvature across slices thicker than the pixels is measured on the slices stretched by their
  // ratio: the surface between two thick slices is not seen, so a bump that lives on one or two of
  // them (noise, a leak on a slice) is smoothed harder across the slices than within them.
  const double hzc = o.stretch_slices ? b.hz * std::max(1.0, b.hz / std::min(b.hx, b.hy)) : b.hz;
  const double speed = std::max(o.region_weight + o.gvf_weight, 1e-6);
  const double dt = 0.9 * std::min(0.5 * hmin / speed, o.curvature_mm > 0 ? 1 / (2 * o.curvature_mm * inv2) : 1e9);

  // Reinitialisation towards a signed distance (Sussman, Smereka & Osher 1994; Godunov upwind),
  // keeping the zero level where it is.
  std::vector<float> tmp(n);
  auto reinit = [&](int iters, double within) {
    const std::vector<float> phi0 = phi;
    const double dtr = 0.5 * hmin;
    for (int it = 0; it < iters; ++it) {
      for_slices(b, o.parallel, [&](int z) {
        for (int y = 0; y < b.ny; ++y)
          for (int x = 0; x < b.nx; ++x) {
            const std::size_t p = b.at(x, y, z);
            if (std::abs(phi0[p]) > within) {
              tmp[p] = phi[p];
              continue;
            }
            const double S = phi0[p] / std::sqrt(double(phi0[p]) * phi0[p] + hmin * hmin);
            double g2 = 0;
            auto axis = [&](double c, double m, double pl, double hh) {
              const double a = (c - m) / hh, bq = (pl - c) / hh;
              if (S > 0) g2 += std::max(std::pow(std::max(a, 0.0), 2), std::pow(std::min(bq, 0.0), 2));
              else g2 += std::max(std::pow(std::min(a, 0.0), 2), std::pow(std::max(bq, 0.0), 2));
            };
            const double c = phi[p];
            axis(c, x > 0 ? phi[b.at(x - 1, y, z)] : c, x < b.nx - 1 ? phi[b.at(x + 1, y, z)] : c, b.hx);
            axis(c, y > 0 ? phi[b.at(x, y - 1, z)] : c, y < b.ny - 1 ? phi[b.at(x, y + 1, z)] : c, b.hy);
            if (b.nz > 1) axis(c, z > 0 ? phi[b.at(x, y, z - 1)] : c, z < b.nz - 1 ? phi[b.at(x, y, z + 1)] : c, b.hz);
            tmp[p] = float(c - dtr * S * (std::sqrt(g2) - 1));
          }
      });
      phi.swap(tmp);
    }
  };
  reinit(int(std::ceil(o.max_grow_mm / (0.5 * hmin))) + 4, std::numeric_limits<double>::infinity());

  // Region competition with local statistics (Chan & Vese's two-region energy over a window
  // around each point, as Lankton & Tannenbaum localise it): a point joins where its HU lies on
  // the organ's side of half-way between the mean inside and the mean outside the surface near
  // it, with unit speed at either mean; where the two means differ by less than min_contrast_hu
  // (no visible wall) the speed fades to 0 and the surface stays. The window term R caps it.
  std::vector<float> Freg = R;
  std::vector<float> Wc(n, 1.f);  // curvature weight: 1 where no wall is seen, less where one is
  const int rx = std::max(1, int(std::lround(o.local_radius_mm / b.hx))), ry = std::max(1, int(std::lround(o.local_radius_mm / b.hy))),
            rz = b.nz > 1 ? std::max(o.local_min_slices, int(std::lround(o.local_radius_mm / b.hz))) : 0;
  auto local_region = [&] {
    if (o.local_radius_mm <= 0) return;
    std::vector<float> hi_(n), hI(n), ho(n), oI(n);
    for (std::size_t p = 0; p < n; ++p) {
      const bool in = phi[p] < 0;
      hi_[p] = in, hI[p] = in ? sm[p] : 0.f, ho[p] = !in, oI[p] = in ? 0.f : sm[p];
    }
    const auto A = box_sum(hi_, b, rx, ry, rz), AI = box_sum(hI, b, rx, ry, rz);
    const auto B = box_sum(ho, b, rx, ry, rz), BI = box_sum(oI, b, rx, ry, rz);
    const double c2 = o.min_contrast_hu * o.min_contrast_hu;
    for (std::size_t p = 0; p < n; ++p) {
      if (A[p] < 0.5f || B[p] < 0.5f) {
        Freg[p] = R[p];
        continue;
      }
      const double mi = AI[p] / A[p], mo = BI[p] / B[p], d = mo - mi;
      const double F = std::clamp((mo + mi - 2 * sm[p]) * d / std::max(d * d, c2), -1.0, 1.0);
      Freg[p] = float(F > 0 ? std::min(F, double(R[p])) : F);  // the window only vetoes growth
      if (o.contrast_curvature_hu > 0) Wc[p] = float(1 / (1 + d * d / (o.contrast_curvature_hu * o.contrast_curvature_hu)));
    }
  };
  local_region();

  auto count_inside = [&] {
    std::int64_t c = 0;
    for (std::size_t p = 0; p < n; ++p) c += phi[p] < 0 || core[p];
    return c;
  };
  // Convergence is judged over the time in which a front at unit speed crosses one pixel (the
  // curvature term's stable step shrinks with the pixel², so a count of steps would stop a slow
  // front on fine pixels too early).
  const int check_every = std::max(10, int(std::ceil(std::min(b.hx, b.hy) / dt)));
  const double band_mm = 3 * std::max({b.hx, b.hy, b.nz > 1 ? b.hz : b.hx});
  std::int64_t last = count_inside(), stable_since = 0;
  int step = 0;
  for (; step < o.max_steps; ++step) {
    for_slices(b, o.parallel, [&](int z) {
      for (int y = 0; y < b.ny; ++y)
        for (int x = 0; x < b.nx; ++x) {
          const std::size_t p = b.at(x, y, z);
          const double c = phi[p];
          // Narrow band: far from the surface φ only carries the distance (kept up by the
          // reinitialisation over the whole box), and the zero level moves far less than the
          // band between two reinitialisations.
          if (std::abs(c) > band_mm) {
            tmp[p] = float(c);
            continue;
          }
          const double xm = x > 0 ? phi[b.at(x - 1, y, z)] : c, xp = x < b.nx - 1 ? phi[b.at(x + 1, y, z)] : c;
          const double ym = y > 0 ? phi[b.at(x, y - 1, z)] : c, yp = y < b.ny - 1 ? phi[b.at(x, y + 1, z)] : c;
          const double zm = z > 0 ? phi[b.at(x, y, z - 1)] : c, zp = z < b.nz - 1 ? phi[b.at(x, y, z + 1)] : c;
          const double dxm = (c - xm) / b.hx, dxp = (xp - c) / b.hx;
          const double dym = (c - ym) / b.hy, dyp = (yp - c) / b.hy;
          const double dzm = (c - zm) / b.hz, dzp = (zp - c) / b.hz;
          // Region: −F |∇φ| upwind (Osher & Sethian).
          const double F = o.region_weight * Freg[p];
          double g2;
          if (F > 0)
            g2 = std::pow(std::max(dxm, 0.0), 2) + std::pow(std::min(dxp, 0.0), 2) + std::pow(std::max(dym, 0.0), 2) +
                 std::pow(std::min(dyp, 0.0), 2) + std::pow(std::max(dzm, 0.0), 2) + std::pow(std::min(dzp, 0.0), 2);
          else
            g2 = std::pow(std::min(dxm, 0.0), 2) + std::pow(std::max(dxp, 0.0), 2) + std::pow(std::min(dym, 0.0), 2) +
                 std::pow(std::max(dyp, 0.0), 2) + std::pow(std::min(dzm, 0.0), 2) + std::pow(std::max(dzp, 0.0), 2);
          double rate = -F * std::sqrt(g2);
          // GVF advection: −v·∇φ upwind.
          const double vx = o.gvf_weight * u[p], vy = o.gvf_weight * v[p], vz = o.gvf_weight * w[p];
          rate -= vx * (vx > 0 ? dxm : dxp) + vy * (vy > 0 ? dym : dyp) + vz * (vz > 0 ? dzm : dzp);
          // Curvature: ε κ |∇φ| by central differences.
          if (o.curvature_mm > 0) {
            const double px = (xp - xm) / (2 * b.hx), py = (yp - ym) / (2 * b.hy), pz = (zp - zm) / (2 * hzc);
            const double pxx = (xp - 2 * c + xm) / (b.hx * b.hx), pyy = (yp - 2 * c + ym) / (b.hy * b.hy),
                         pzz = (zp - 2 * c + zm) / (hzc * hzc);
            auto P = [&](int X, int Y, int Z) {
              return double(phi[b.at(std::clamp(X, 0, b.nx - 1), std::clamp(Y, 0, b.ny - 1), std::clamp(Z, 0, b.nz - 1))]);
            };
            const double pxy = (P(x + 1, y + 1, z) - P(x + 1, y - 1, z) - P(x - 1, y + 1, z) + P(x - 1, y - 1, z)) / (4 * b.hx * b.hy);
            const double pxz = (P(x + 1, y, z + 1) - P(x + 1, y, z - 1) - P(x - 1, y, z + 1) + P(x - 1, y, z - 1)) / (4 * b.hx * hzc);
            const double pyz = (P(x, y + 1, z + 1) - P(x, y + 1, z - 1) - P(x, y - 1, z + 1) + P(x, y - 1, z - 1)) / (4 * b.hy * hzc);
            const double gg = px * px + py * py + pz * pz;
            if (gg > 1e-12)
              rate += o.curvature_mm * Wc[p] *
                      (pxx * (py * py + pz * pz) + pyy * (px * px + pz * pz) + pzz * (px * px + py * py) -
                       2 * (px * py * pxy + px * pz * pxz + py * pz * pyz)) / gg;
          }
          double nv = c + dt * rate;
          nv = std::max(nv, double(limit[p]));
          if (core[p]) nv = std::min(nv, -0.5 * hmin);  // the start's core stays inside
          tmp[p] = float(nv);
        }
    });
    phi.swap(tmp);
    // Every 5 steps the distance is restored near the surface, every 20 over the whole box (the
    // zero level moves under a pixel in between); the local means change slowly with the surface.
    if ((step + 1) % 20 == 0) reinit(2, std::numeric_limits<double>::infinity()), local_region();
    else if ((step + 1) % 5 == 0) reinit(2, 2 * band_mm);
    if ((step + 1) % check_every == 0) {
      const std::int64_t now = count_inside();
      if (std::llabs(now - last) <= std::max<std::int64_t>(1, last / 2000)) {
        if (++stable_since >= 2) {
          res.converged = true;
          ++step;
          break;
        }
      } else {
        stable_since = 0;
      }
      last = now;
    }
  }
  res.steps = step;
  std::vector<std::uint8_t> in(n);
  for (std::size_t p = 0; p < n; ++p) in[p] = phi[p] < 0 || core[p];
  const std::vector<std::uint8_t> out = simple_topology(in, core, b);
  res.first_k = NZ, res.last_k = -1;
  for (int z = 0; z < b.nz; ++z)
    for (int y = 0; y < b.ny; ++y)
      for (int x = 0; x < b.nx; ++x)
        if (out[b.at(x, y, z)]) {
          res.mask[std::size_t(g.offset(b.i0 + x, b.j0 + y, b.k0 + z))] = 1;
          ++res.voxels;
          res.first_k = std::min<std::int64_t>(res.first_k, b.k0 + z);
          res.last_k = std::max<std::int64_t>(res.last_k, b.k0 + z);
        }
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  res.box_voxels = std::int64_t(n);
  // An upper bound of the per-voxel arrays alive at once: ≈ 30 float arrays (HU, smoothed HU, R,
  // F, w_c, φ and its copies, the limit, distances, the GVF's 10, the local sums' 8 with their
  // box-filter copies) and 6 byte masks.
  res.box_mib = double(n) * (4.0 * 30 + 6) / (1024.0 * 1024.0);
  char note[300];
  std::snprintf(note, sizeof note,
                "3-D surface: %lld → %lld voxels (%+.1f %%), slices %lld–%lld, %d steps%s, %.2f s, box %lld voxels (≤ %.0f MiB)",
                static_cast<long long>(res.start_voxels), static_cast<long long>(res.voxels),
                100.0 * double(res.voxels - res.start_voxels) / double(res.start_voxels),
                static_cast<long long>(res.first_k), static_cast<long long>(res.last_k), res.steps,
                res.converged ? "" : " (step limit)", res.seconds, static_cast<long long>(res.box_voxels), res.box_mib);
  res.note = note;
  return res;
}

}  // namespace organsmith::seg
