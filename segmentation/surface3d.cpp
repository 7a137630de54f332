// Over 400 lines: the level set's evolution is one loop whose passes (region speed, GVF
// advection, curvature, reinitialisation, local statistics) share the working box's arrays and
// the narrow band; its grid tools are in detail/grid3d.
#include "segmentation/surface3d.h"

#include "segmentation/detail/grid3d.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <tuple>
#include <type_traits>

namespace organsmith::seg {

using detail::Box;
using detail::Grad;
using detail::box_sum;
using detail::central;
using detail::distance_sq_mm2;
using detail::for_slices;
using detail::gaussian;
using detail::simple_topology;

bool BoxMask::at(std::int64_t i, std::int64_t j, std::int64_t k) const {
  i -= origin_vox[0], j -= origin_vox[1], k -= origin_vox[2];
  if (i < 0 || j < 0 || k < 0 || i >= size_vox[0] || j >= size_vox[1] || k >= size_vox[2]) return false;
  return inside[std::size_t(i + size_vox[0] * (j + size_vox[1] * k))] != 0;
}

std::vector<std::uint8_t> BoxMask::on_grid(const ImageGrid& g) const {
  std::vector<std::uint8_t> out(std::size_t(g.voxel_count()), 0);
  for (std::int64_t k = 0; k < size_vox[2]; ++k)
    for (std::int64_t j = 0; j < size_vox[1]; ++j)
      std::memcpy(out.data() + g.offset(origin_vox[0], origin_vox[1] + j, origin_vox[2] + k),
                  inside.data() + size_vox[0] * (j + size_vox[1] * k), std::size_t(size_vox[0]));
  return out;
}

BoxMask box_mask_of(const std::uint8_t* values, const ImageGrid& g, std::uint8_t value) {
  const std::int64_t NX = g.size_vox[0], NY = g.size_vox[1], NZ = g.size_vox[2];
  std::int64_t lo[3] = {NX, NY, NZ}, hi[3] = {-1, -1, -1};
  for (std::int64_t k = 0; k < NZ; ++k)
    for (std::int64_t j = 0; j < NY; ++j) {
      const std::uint8_t* row = values + g.offset(0, j, k);  // a row is contiguous, x fastest
      const void* first = std::memchr(row, value, std::size_t(NX));   // (vectorised: most rows hold none)
      if (!first) continue;
      const void* last = memrchr(row, value, std::size_t(NX));
      lo[0] = std::min<std::int64_t>(lo[0], static_cast<const std::uint8_t*>(first) - row);
      hi[0] = std::max<std::int64_t>(hi[0], static_cast<const std::uint8_t*>(last) - row);
      lo[1] = std::min(lo[1], j), hi[1] = std::max(hi[1], j);
      lo[2] = std::min(lo[2], k), hi[2] = std::max(hi[2], k);
    }
  BoxMask m;
  if (hi[0] < 0) return m;
  for (int a = 0; a < 3; ++a) m.origin_vox[std::size_t(a)] = lo[a], m.size_vox[std::size_t(a)] = hi[a] - lo[a] + 1;
  m.inside.resize(std::size_t(m.size_vox[0] * m.size_vox[1] * m.size_vox[2]));
  std::size_t q = 0;
  for (std::int64_t k = lo[2]; k <= hi[2]; ++k)
    for (std::int64_t j = lo[1]; j <= hi[1]; ++j)
      for (std::int64_t i = lo[0]; i <= hi[0]; ++i) m.inside[q++] = values[std::size_t(g.offset(i, j, k))] == value;
  return m;
}

namespace {

/// The GVF field (Xu & Prince) of the 3-D edge map of the box's HU, in mm, normalised to |v| ≤ 1.
struct GvfField {
  std::vector<float> u, v, w;
};

GvfField gvf_field(const std::vector<float>& hu, const Box& b, const Surface3dOptions& o) {
  const std::size_t n = b.size();
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
    const double hx2 = b.hx * b.hx, hy2 = b.hy * b.hy, hz2 = b.hz * b.hz;
    // One explicit step of a component `a` (target `d`) along a row: x-neighbours clamped at the
    // row's ends, the rows either side in y and z given (clamped by the caller). The interior
    // loop has no clamps, so that the compiler vectorises it.
    auto row_step = [&](const float* a, const float* d, const float* bbr, const float* aym, const float* ayp,
                        const float* azm, const float* azp, float* out) {
      auto cell = [&](int x, int xm, int xp) {
        const double L = (a[xm] + a[xp] - 2.0 * a[x]) / hx2 + (aym[x] + ayp[x] - 2.0 * a[x]) / hy2 +
                         (azm[x] + azp[x] - 2.0 * a[x]) / hz2;
        out[x] = float(a[x] + dt * (mu * L - bbr[x] * (a[x] - d[x])));
      };
      cell(0, 0, std::min(1, b.nx - 1));
      for (int x = 1; x < b.nx - 1; ++x) {
        const double L = (a[x - 1] + a[x + 1] - 2.0 * a[x]) / hx2 + (aym[x] + ayp[x] - 2.0 * a[x]) / hy2 +
                         (azm[x] + azp[x] - 2.0 * a[x]) / hz2;
        out[x] = float(a[x] + dt * (mu * L - bbr[x] * (a[x] - d[x])));
      }
      if (b.nx > 1) cell(b.nx - 1, b.nx - 2, b.nx - 1);
    };
    for (int it = 0; it < o.gvf_iterations; ++it) {
      for_slices(b, o.parallel, [&](int z) {
        const int zm = std::max(z - 1, 0), zp = std::min(z + 1, b.nz - 1);
        for (int y = 0; y < b.ny; ++y) {
          const int ym = std::max(y - 1, 0), yp = std::min(y + 1, b.ny - 1);
          const std::size_t r = b.at(0, y, z), rym = b.at(0, ym, z), ryp = b.at(0, yp, z), rzm = b.at(0, y, zm),
                            rzp = b.at(0, y, zp);
          for (auto [a, d, o2] : {std::tuple{&u, &fx, &u2}, std::tuple{&v, &fy, &v2}, std::tuple{&w, &fz, &w2}}) {
            const float* A = a->data();
            row_step(A + r, d->data() + r, bb.data() + r, A + rym, A + ryp, A + rzm, A + rzp, o2->data() + r);
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

  return {std::move(u), std::move(v), std::move(w)};
}

}  // namespace

Surface3dResult evolve_surface3d(const Volume& vol, const BoxMask& start, const Surface3dOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  Surface3dResult res;
  const auto& g = vol.grid;
  const std::int64_t NX = g.size_vox[0], NY = g.size_vox[1], NZ = g.size_vox[2];
  // The start's box (of its inside voxels), grown by the margin.
  std::int64_t lo[3] = {NX, NY, NZ}, hi[3] = {-1, -1, -1};
  for (std::int64_t k = 0; k < start.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < start.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < start.size_vox[0]; ++i)
        if (start.inside[std::size_t(i + start.size_vox[0] * (j + start.size_vox[1] * k))]) {
          const std::int64_t c[3] = {start.origin_vox[0] + i, start.origin_vox[1] + j, start.origin_vox[2] + k};
          for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]), hi[a] = std::max(hi[a], c[a]);
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
        s0[b.at(x, y, z)] = start.at(b.i0 + x, b.j0 + y, b.k0 + z) ? 1 : 0;
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
  GvfField field = gvf_field(hu, b, o);
  const std::vector<float>& u = field.u;
  const std::vector<float>& v = field.v;
  const std::vector<float>& w = field.w;

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

  // The points a pass visits, as runs of a row: those with |φ| ≤ `within` (the narrow band; every
  // point where `within` is infinite). A pass writes its runs' new values to tmp, then copies
  // them back: points outside the runs keep their value, as in a pass over the box that skips them.
  struct Run {
    int y, z, x0, x1;  // x0 ≤ x < x1
  };
  auto runs_within = [&](double within, std::vector<Run>& runs) {
    runs.clear();
    for (int z = 0; z < b.nz; ++z)
      for (int y = 0; y < b.ny; ++y) {
        const float* P = phi.data() + b.at(0, y, z);
        for (int x = 0; x < b.nx;) {
          if (!(std::abs(P[x]) <= within)) {
            ++x;
            continue;
          }
          const int x0 = x;
          while (x < b.nx && std::abs(P[x]) <= within) ++x;
          runs.push_back({y, z, x0, x});
        }
      }
  };
  auto over_runs = [&](const std::vector<Run>& runs, auto&& f) {
    if (o.parallel)
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, runs.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) f(runs[i]);
      });
    else
      for (const Run& q : runs) f(q);
  };
  std::vector<float> tmp(n);
  auto keep_runs = [&](const std::vector<Run>& runs) {
    over_runs(runs, [&](const Run& q) {
      const std::size_t r = b.at(q.x0, q.y, q.z);
      std::copy(tmp.begin() + std::ptrdiff_t(r), tmp.begin() + std::ptrdiff_t(r + std::size_t(q.x1 - q.x0)),
                phi.begin() + std::ptrdiff_t(r));
    });
  };
  /// Rows either side of row (y, z), clamped at the box's faces (a neighbour row past a face is the
  /// row itself: one-sided differences there).
  struct Rows {
    const float *c, *ym, *yp, *zm, *zp, *ypzp, *ypzm, *ymzp, *ymzm;
  };
  auto rows_of = [&](int y, int z) {
    const int ym = std::max(y - 1, 0), yp = std::min(y + 1, b.ny - 1), zm = std::max(z - 1, 0), zp = std::min(z + 1, b.nz - 1);
    const float* F0 = phi.data();
    return Rows{F0 + b.at(0, y, z),   F0 + b.at(0, ym, z),  F0 + b.at(0, yp, z),  F0 + b.at(0, y, zm), F0 + b.at(0, y, zp),
                F0 + b.at(0, yp, zp), F0 + b.at(0, yp, zm), F0 + b.at(0, ym, zp), F0 + b.at(0, ym, zm)};
  };
  /// f(x, x − 1, x + 1) along a run, the x-neighbours clamped at the row's ends; the interior loop
  /// has no clamps, so that it can vectorise.
  auto along = [&](const Run& q, auto&& f) __attribute__((always_inline)) {
    int x = q.x0;
    if (x == 0) f(0, 0, std::min(1, b.nx - 1)), ++x;
    const int end = std::min(q.x1, b.nx - 1);
    for (; x < end; ++x) f(x, x - 1, x + 1);
    if (x < q.x1) f(x, x - 1, x);  // x = nx − 1 (nx ≥ 2 here)
  };

  // Reinitialisation towards a signed distance (Sussman, Smereka & Osher 1994; Godunov upwind),
  // keeping the zero level where it is; over the points with |φ| ≤ `within` at the start.
  std::vector<Run> near;
  std::vector<double> S;  // the sign of φ at the start of a reinitialisation, smoothed
  auto reinit = [&](int iters, double within) {
    S.resize(n);
    const double dtr = 0.5 * hmin;
    // Godunov's upwind |∇φ|² along one axis (c the point, m and pl its neighbours).
    auto axis = [](double s, double c, double m, double pl, double hh) __attribute__((always_inline)) {
      const double a = (c - m) / hh, bq = (pl - c) / hh;
      const double ap = std::max(a, 0.0), am = std::min(a, 0.0), bp = std::max(bq, 0.0), bm = std::min(bq, 0.0);
      const double pos = std::max(ap * ap, bm * bm), neg = std::max(am * am, bp * bp);  // (both: no branch)
      return s > 0 ? pos : neg;
    };
    runs_within(within, near);
    over_runs(near, [&](const Run& q) {
      const std::size_t r = b.at(0, q.y, q.z);
      for (int x = q.x0; x < q.x1; ++x) S[r + x] = phi[r + x] / std::sqrt(double(phi[r + x]) * phi[r + x] + hmin * hmin);
    });
    for (int it = 0; it < iters; ++it) {
      over_runs(near, [&](const Run& q) {
        const Rows R = rows_of(q.y, q.z);
        const std::size_t r = b.at(0, q.y, q.z);
        along(q, [&](int x, int xm, int xp) __attribute__((always_inline)) {
          const double c = R.c[x];
          double g2 = 0;
          g2 += axis(S[r + x], c, R.c[xm], R.c[xp], b.hx);
          g2 += axis(S[r + x], c, R.ym[x], R.yp[x], b.hy);
          g2 += axis(S[r + x], c, R.zm[x], R.zp[x], b.hz);  // (0 on a single slice: both neighbours are the point)
          tmp[r + x] = float(c - dtr * S[r + x] * (std::sqrt(g2) - 1));
        });
      });
      keep_runs(near);
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
  // Window sums: A and A·I over the inside, B·I over the outside; the outside's count is the
  // window's count Nw less A (sums of ones and zeros are exact in float).
  std::vector<float> A, AI, BI, Nw, scratch;
  if (o.local_radius_mm > 0) Nw.assign(n, 1.f), scratch.resize(n), box_sum(Nw, scratch, b, rx, ry, rz);
  auto local_region = [&] {
    if (o.local_radius_mm <= 0) return;
    A.resize(n), AI.resize(n), BI.resize(n);
    for (std::size_t p = 0; p < n; ++p) {
      const bool in = phi[p] < 0;
      A[p] = in, AI[p] = in ? sm[p] : 0.f, BI[p] = in ? 0.f : sm[p];
    }
    box_sum(A, scratch, b, rx, ry, rz), box_sum(AI, scratch, b, rx, ry, rz), box_sum(BI, scratch, b, rx, ry, rz);
    const double c2 = o.min_contrast_hu * o.min_contrast_hu;
    for (std::size_t p = 0; p < n; ++p) {
      const float B = Nw[p] - A[p];
      if (A[p] < 0.5f || B < 0.5f) {
        Freg[p] = R[p];
        continue;
      }
      const double mi = AI[p] / A[p], mo = BI[p] / B, d = mo - mi;
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
  // The narrow band (points outside it only carry the distance, kept up by the reinitialisation
  // over the whole box, and the zero level moves far less than the band between two
  // reinitialisations): rebuilt after each reinitialisation, the only points a step moves.
  std::vector<Run> band;
  const bool curve = o.curvature_mm > 0;
  std::vector<float> core_f(core.begin(), core.end());  // (as float: one element width with φ in the loop)
  // One step along a run. Rows past the box's faces are the row itself and x-neighbours past them
  // the point itself (one-sided differences there); branches are selects, so that the interior
  // loop vectorises.
  auto step_run = [&](const Run& q) {
    const Rows R = rows_of(q.y, q.z);
    const std::size_t r = b.at(0, q.y, q.z);
    const float *P = R.c, *Pym = R.ym, *Pyp = R.yp, *Pzm = R.zm, *Pzp = R.zp, *Pypzp = R.ypzp, *Pypzm = R.ypzm,
                *Pymzp = R.ymzp, *Pymzm = R.ymzm;
    const float *Fr = Freg.data() + r, *Ur = u.data() + r, *Vr = v.data() + r, *Wr = w.data() + r,
                *Wcr = Wc.data() + r, *Lr = limit.data() + r;
    const float* Cr = core_f.data() + r;
    float* out = tmp.data() + r;
    auto sq = [](double t) __attribute__((always_inline)) { return t * t; };
    auto cell = [&](auto with_curvature, int x, int xm_i, int xp_i) __attribute__((always_inline)) {
      const double c = P[x];
      const double xm = P[xm_i], xp = P[xp_i], ym = Pym[x], yp = Pyp[x], zm = Pzm[x], zp = Pzp[x];
      const double dxm = (c - xm) / b.hx, dxp = (xp - c) / b.hx;
      const double dym = (c - ym) / b.hy, dyp = (yp - c) / b.hy;
      const double dzm = (c - zm) / b.hz, dzp = (zp - c) / b.hz;
      // Region: −F |∇φ| upwind (Osher & Sethian).
      const double F = o.region_weight * Fr[x];
      const double g2p = sq(std::max(dxm, 0.0)) + sq(std::min(dxp, 0.0)) + sq(std::max(dym, 0.0)) +
                         sq(std::min(dyp, 0.0)) + sq(std::max(dzm, 0.0)) + sq(std::min(dzp, 0.0));
      const double g2n = sq(std::min(dxm, 0.0)) + sq(std::max(dxp, 0.0)) + sq(std::min(dym, 0.0)) +
                         sq(std::max(dyp, 0.0)) + sq(std::min(dzm, 0.0)) + sq(std::max(dzp, 0.0));
      double rate = -F * std::sqrt(F > 0 ? g2p : g2n);
      // GVF advection: −v·∇φ upwind.
      const double vx = o.gvf_weight * Ur[x], vy = o.gvf_weight * Vr[x], vz = o.gvf_weight * Wr[x];
      rate -= vx * (vx > 0 ? dxm : dxp) + vy * (vy > 0 ? dym : dyp) + vz * (vz > 0 ? dzm : dzp);
      // Curvature: ε κ |∇φ| by central differences.
      if constexpr (decltype(with_curvature)::value) {
        const double px = (xp - xm) / (2 * b.hx), py = (yp - ym) / (2 * b.hy), pz = (zp - zm) / (2 * hzc);
        const double pxx = (xp - 2 * c + xm) / (b.hx * b.hx), pyy = (yp - 2 * c + ym) / (b.hy * b.hy),
                     pzz = (zp - 2 * c + zm) / (hzc * hzc);
        const double pxy = (double(Pyp[xp_i]) - Pym[xp_i] - Pyp[xm_i] + Pym[xm_i]) / (4 * b.hx * b.hy);
        const double pxz = (double(Pzp[xp_i]) - Pzm[xp_i] - Pzp[xm_i] + Pzm[xm_i]) / (4 * b.hx * hzc);
        const double pyz = (double(Pypzp[x]) - Pypzm[x] - Pymzp[x] + Pymzm[x]) / (4 * b.hy * hzc);
        const double gg = px * px + py * py + pz * pz;
        const double k = o.curvature_mm * Wcr[x] *
                         (pxx * (py * py + pz * pz) + pyy * (px * px + pz * pz) + pzz * (px * px + py * py) -
                          2 * (px * py * pxy + px * pz * pxz + py * pz * pyz)) / gg;
        const double with_k = rate + k;  // (computed either way: a select, no branch)
        rate = gg > 1e-12 ? with_k : rate;
      }
      double nv = c + dt * rate;
      nv = std::max(nv, double(Lr[x]));
      const double held = std::min(nv, -0.5 * hmin);
      nv = Cr[x] > 0 ? held : nv;  // the start's core stays inside
      out[x] = float(std::abs(c) > band_mm ? c : nv);  // a point that left the band stays
    };
    auto cells = [&](auto with_curvature) {
      along(q, [&](int x, int xm, int xp) __attribute__((always_inline)) { cell(with_curvature, x, xm, xp); });
    };
    if (curve) cells(std::true_type{});
    else cells(std::false_type{});
  };
  runs_within(band_mm, band);
  int step = 0;
  for (; step < o.max_steps; ++step) {
    over_runs(band, step_run);
    keep_runs(band);
    // Every 5 steps the distance is restored near the surface, every 20 over the whole box (the
    // zero level moves under a pixel in between); the local means change slowly with the surface.
    // Between two reinitialisations only the band's points move.
    if ((step + 1) % 20 == 0) reinit(2, std::numeric_limits<double>::infinity()), local_region(), runs_within(band_mm, band);
    else if ((step + 1) % 5 == 0) reinit(2, 2 * band_mm), runs_within(band_mm, band);
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
  res.mask.origin_vox = {b.i0, b.j0, b.k0};
  res.mask.size_vox = {b.nx, b.ny, b.nz};
  res.mask.inside.assign(n, 0);
  for (int z = 0; z < b.nz; ++z)
    for (int y = 0; y < b.ny; ++y)
      for (int x = 0; x < b.nx; ++x)
        if (out[b.at(x, y, z)]) {
          res.mask.inside[b.at(x, y, z)] = 1;
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
