// The 3-D GVF surface on a synthetic thick-slice scan built with the three failure kinds the
// slices leave: a band of the organ cut straight along its body, the last sections past a stop,
// and a narrow lobe taken in through a gap in the wall to a bile-like neighbour. The surface must
// fill the first two, drop the third, not enter the neighbour, and keep a simple topology.

#include "segmentation/presets.h"
#include "segmentation/detail/grid3d.h"
#include "segmentation/surface3d.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

using namespace organsmith;
using namespace organsmith::seg;

namespace {

struct Scene {
  Volume ct;
  std::vector<std::uint8_t> truth, neighbour, start, band, ends, lobe;
};

// 1 × 1 × 3 mm voxels, 64 × 64 × 30. Organ: bile (5 HU), elliptic sections of semi-axes 12 × 9 mm
// narrowing to a blunt end 30 mm either side of the centre (x²/a² + y²/b² + (z/c)⁴ ≤ 1); a band
// 3 mm wide cut off its +x side over 24 mm;
// liver (60 HU) around; a bile-like neighbour (10 HU) 3 mm beyond the organ's +x side, with a
// 4 mm-wide channel through that wall on two slices; 8 HU of noise.
Scene make_scene() {
  Scene s;
  auto& g = s.ct.grid;
  g.size_vox = {64, 64, 30};
  g.spacing_mm = {1.0, 1.0, 3.0};
  const std::size_t n = std::size_t(g.voxel_count());
  s.ct.hu.assign(n, 60.f);
  for (auto* v : {&s.truth, &s.neighbour, &s.start, &s.band, &s.ends, &s.lobe}) v->assign(n, 0);
  const double cx = 26, cy = 32, cz = 45;  // mm
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 8);
  int last_k = -1;
  for (int k = 0; k < 30; ++k)
    for (int j = 0; j < 64; ++j)
      for (int i = 0; i < 64; ++i) {
        const double x = i - cx, y = j - cy, z = 3.0 * k - cz;
        const std::size_t p = std::size_t(g.offset(i, j, k));
        // A blunt end (z⁴): the fundus is rounded, its last sections are not points.
        const bool organ = (x * x) / 144 + (y * y) / 81 + std::pow(z / 30, 4) <= 1;
        const double nx = x - 23;  // neighbour centred 23 mm along +x: its near side 3 mm off the organ
        const bool nb = (nx * nx) / 64 + (y * y) / 64 + (z * z) / 400 <= 1;
        const bool channel = x > 8 && x < 17 && std::abs(y) <= 2 && (k == 14 || k == 15);
        double hu = 60;
        if (organ) hu = 5, s.truth[p] = 1, last_k = std::max(last_k, k);
        if (nb) hu = 10, s.neighbour[p] = 1;
        if (channel && !organ && !nb) hu = 8;
        s.ct.hu[p] = float(hu);
      }
  // The scanner's in-plane blur (a Gaussian of σ = 1 mm: a point spread of 2.4 mm FWHM, a
  // standard body kernel's), then the noise.
  {
    std::vector<float> tmp(n);
    const double w[5] = {0.0545, 0.2442, 0.4026, 0.2442, 0.0545};  // σ = 1 pixel, normalised
    for (int pass = 0; pass < 2; ++pass) {
      for (int k = 0; k < 30; ++k)
        for (int j = 0; j < 64; ++j)
          for (int i = 0; i < 64; ++i) {
            double a = 0;
            for (int t = -2; t <= 2; ++t) {
              const int ii = pass == 0 ? std::clamp(i + t, 0, 63) : i, jj = pass == 1 ? std::clamp(j + t, 0, 63) : j;
              a += w[t + 2] * s.ct.hu[std::size_t(g.offset(ii, jj, k))];
            }
            tmp[std::size_t(g.offset(i, j, k))] = float(a);
          }
      std::copy(tmp.begin(), tmp.end(), s.ct.hu.begin());
    }
    for (auto& v : s.ct.hu) v = float(v + noise(rng));
  }
  for (int k = 0; k < 30; ++k)
    for (int j = 0; j < 64; ++j)
      for (int i = 0; i < 64; ++i) {
        const double x = i - cx, y = j - cy;
        const std::size_t p = std::size_t(g.offset(i, j, k));
        // Voxels of the truth a pixel or more inside its in-plane outline: which side of the wall's
        // blur the boundary pixel falls on is the boundary's placement, not what is tested here.
        auto in_truth = [&](int a, int b2) { return s.truth[std::size_t(g.offset(std::clamp(a, 0, 63), std::clamp(b2, 0, 63), k))] != 0; };
        const bool deep = s.truth[p] && in_truth(i - 1, j) && in_truth(i + 1, j) && in_truth(i, j - 1) && in_truth(i, j + 1);
        const bool band = deep && x > 9 && std::abs(3.0 * k - cz) < 12;  // cut straight along the body
        const bool past_stop = deep && k > last_k - 2;                   // the last two sections
        const bool lobe = !s.truth[p] && x > 8 && x < 20 && std::abs(y) <= 2 && (k == 14 || k == 15);
        s.band[p] = band, s.ends[p] = past_stop, s.lobe[p] = lobe;
        const bool cut = s.truth[p] && ((x > 9 && std::abs(3.0 * k - cz) < 12) || k > last_k - 2);
        s.start[p] = (s.truth[p] && !cut) || lobe;
      }
  return s;
}

Surface3dOptions shipped_options() {
  const OrganPreset p = default_organ_presets().at("gallbladder");
  Surface3dOptions o;
  o.lo_hu = 5 - p.region_below_hu, o.hi_hu = 5 + p.region_above_hu, o.ramp_hu = p.pressure_ramp_hu;
  o.region_sigma_mm = 1.0;
  o.edge_lo_hu = p.edge_window_lo_hu, o.edge_hi_hu = p.edge_window_hi_hu, o.edge_sigma_mm = p.edge_sigma_mm;
  o.gvf_mu = p.gvf_mu, o.gvf_weight = p.surface3d_gvf_weight, o.curvature_mm = p.surface3d_curvature_mm;
  o.max_grow_mm = p.surface3d_max_grow_mm, o.max_steps = p.surface3d_max_steps;
  o.edge_stop_hu_per_mm = p.surface3d_edge_stop_hu_per_mm, o.local_radius_mm = p.surface3d_local_radius_mm;
  o.min_contrast_hu = p.surface3d_min_contrast_hu, o.open_start_mm = p.surface3d_open_start_mm;
  o.contrast_curvature_hu = p.surface3d_contrast_curvature_hu;
  return o;
}

double dice(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
  double ab = 0, na = 0, nb = 0;
  for (std::size_t p = 0; p < a.size(); ++p) ab += a[p] && b[p], na += a[p] != 0, nb += b[p] != 0;
  return 2 * ab / (na + nb);
}

double covered(const std::vector<std::uint8_t>& part, const std::vector<std::uint8_t>& by) {
  double in = 0, all = 0;
  for (std::size_t p = 0; p < part.size(); ++p) all += part[p] != 0, in += part[p] && by[p];
  return in / all;
}

}  // namespace

TEST(Surface3d, FillsTheCutBandAndTheMissingEndsAndDropsALobeTakenInThroughAGap) {
  const Scene s = make_scene();
  const Surface3dResult r = evolve_surface3d(s.ct, box_mask_of(s.start.data(), s.ct.grid, 1), shipped_options());
  const std::vector<std::uint8_t> mask = r.mask.on_grid(s.ct.grid);
  const double band = covered(s.band, mask), ends = covered(s.ends, mask), lobe = covered(s.lobe, mask);
  const double nb = covered(s.neighbour, mask);
  const double d0 = dice(s.start, s.truth), d1 = dice(mask, s.truth);
  std::printf("3-D surface: Dice %.3f → %.3f; band filled %.2f, last two sections %.2f, lobe kept %.2f, neighbour "
              "taken %.3f; %d steps, %.2f s\n", d0, d1, band, ends, lobe, nb, r.steps, r.seconds);
  EXPECT_TRUE(r.converged);
  EXPECT_GE(band, 0.8);
  EXPECT_GE(ends, 0.4);
  EXPECT_LE(lobe, 0.2);
  EXPECT_LE(nb, 0.02);
  // Where it adds, the surface stops on the wall's blur a pixel short of half-way (the outward push
  // halves on a wall), so the Dice gain is smaller than the parts filled.
  EXPECT_GT(d1, d0);
}

TEST(Surface3d, OneComponentWithoutCavitiesOrHolesAndTheSameOnOneThread) {
  const Scene s = make_scene();
  Surface3dOptions o = shipped_options();
  const BoxMask start = box_mask_of(s.start.data(), s.ct.grid, 1);
  const Surface3dResult a = evolve_surface3d(s.ct, start, o);
  o.parallel = false;
  const Surface3dResult b = evolve_surface3d(s.ct, start, o);
  EXPECT_EQ(a.mask.inside, b.mask.inside);
  EXPECT_EQ(a.mask.origin_vox, b.mask.origin_vox);
  const std::vector<std::uint8_t> mask = a.mask.on_grid(s.ct.grid);
  // Flood the background from the grid's faces and the inside from one voxel: together they
  // must cover the grid (no cavity, one component).
  const auto& g = s.ct.grid;
  const int nx = int(g.size_vox[0]), ny = int(g.size_vox[1]), nz = int(g.size_vox[2]);
  std::vector<std::uint8_t> seen(mask.size(), 0);
  std::vector<std::size_t> stack;
  auto flood = [&](std::uint8_t value) {
    while (!stack.empty()) {
      const std::size_t p = stack.back();
      stack.pop_back();
      const int x = int(p % nx), y = int((p / nx) % ny), z = int(p / (std::size_t(nx) * ny));
      const int d[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
      for (const auto& e : d) {
        const int X = x + e[0], Y = y + e[1], Z = z + e[2];
        if (X < 0 || Y < 0 || Z < 0 || X >= nx || Y >= ny || Z >= nz) continue;
        const std::size_t q = std::size_t(g.offset(X, Y, Z));
        if (!seen[q] && mask[q] == value) seen[q] = 1, stack.push_back(q);
      }
    }
  };
  for (std::size_t p = 0; p < mask.size(); ++p) {
    const int x = int(p % nx), y = int((p / nx) % ny), z = int(p / (std::size_t(nx) * ny));
    if ((x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1) && !mask[p] && !seen[p])
      seen[p] = 1, stack.push_back(p);
  }
  flood(0);
  for (std::size_t p = 0; p < mask.size(); ++p)
    if (mask[p]) {
      seen[p] = 1, stack.push_back(p);
      break;
    }
  flood(1);
  std::size_t missed = 0;
  for (auto v : seen) missed += v == 0;
  EXPECT_EQ(missed, 0u) << "voxels in a cavity or in a second component";
  EXPECT_GT(a.voxels, 0);
}

TEST(Surface3d, DistanceTransformIsExactOnAnAnisotropicGrid) {
  const int nx = 9, ny = 7, nz = 5;
  const double hx = 0.7, hy = 1.1, hz = 3.0;
  std::vector<std::uint8_t> f(std::size_t(nx * ny * nz), 0);
  std::mt19937 rng(3);
  for (auto& v : f) v = (rng() % 17) == 0;
  const auto d = detail::distance_sq_mm2(f, nx, ny, nz, hx, hy, hz);
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        double best = INFINITY;
        for (int c = 0; c < nz; ++c)
          for (int b = 0; b < ny; ++b)
            for (int a = 0; a < nx; ++a)
              if (f[std::size_t((c * ny + b) * nx + a)])
                best = std::min(best, std::pow((x - a) * hx, 2) + std::pow((y - b) * hy, 2) + std::pow((z - c) * hz, 2));
        EXPECT_NEAR(d[std::size_t((z * ny + y) * nx + x)], best, 1e-4 * std::max(1.0, best));
      }
}
