// GVF field: agreement with ITK's filter, multigrid versus the explicit iteration, stability.

#include "segmentation/edge_map.h"
#include "segmentation/gvf.h"
#include "segmentation/gvf_itk_reference.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

using namespace organsmith::seg;

namespace {

double sq(double v) { return v * v; }

// An image of a bright disc and a dark rectangle in noise, in HU, turned into an edge map the
// way the pipeline does it.
Image2f test_edge_map(int w, int h, unsigned seed = 7) {
  std::vector<float> hu(std::size_t(w) * h);
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 10.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double dx = x - 0.4 * w, dy = y - 0.5 * h;
      float v = 60.0f;
      if (dx * dx + dy * dy < sq(0.2 * w)) v = 10.0f;
      if (x > 0.7 * w && x < 0.9 * w && y > 0.2 * h && y < 0.5 * h) v = -100.0f;
      hu[std::size_t(y) * w + x] = v + noise(rng);
    }
  return edge_map(hu.data(), w, h, 0.8, 0.8, {-150, 150, 1.5});
}



double max_abs(const Image2f& a) {
  double m = 0;
  for (float v : a.px) m = std::max(m, double(std::abs(v)));
  return m;
}

double max_diff(const Image2f& a, const Image2f& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.px.size(); ++i) m = std::max(m, double(std::abs(a.px[i] - b.px[i])));
  return m;
}

}  // namespace

TEST(Gvf, JacobiMatchesItkWithItsTimeStep) {
  const Image2f f = test_edge_map(96, 80);
  Image2f fx, fy;
  edge_gradient(f, fx, fy);
  const double mu = 0.2;
  const int iterations = 60;
  Image2f u(f.width, f.height), v(f.width, f.height);
  const double itk_dt = gvf_itk_reference(fx.px.data(), fy.px.data(), f.width, f.height, mu, iterations, u.px.data(),
                                          v.px.data());
  EXPECT_NEAR(itk_dt, 1.0 / (4.0 * mu), 1e-12);  // ITK's own CFL choice, whatever SetTimeStep said
  GvfOptions o;
  o.mu = mu;
  o.iterations = iterations;
  o.time_step = itk_dt;
  const GvfField g = gvf_jacobi(f, o);
  const double scale = std::max(max_abs(u), max_abs(v));
  ASSERT_GT(scale, 0.0);
  EXPECT_LE(max_diff(g.u, u) / scale, 1e-3);
  EXPECT_LE(max_diff(g.v, v) / scale, 1e-3);
  // …and the field did change from its start (otherwise the comparison would prove nothing).
  EXPECT_GT(max_diff(g.u, fx) / scale, 1e-2);
}

TEST(Gvf, MultigridReachesTheSteadyStateOfTheExplicitScheme) {
  const Image2f f = test_edge_map(64, 48, 3);
  GvfOptions o;
  o.mu = 0.2;
  o.iterations = 30000;  // explicit diffusion across 64 pixels needs ~N² steps
  const GvfField ref = gvf_jacobi(f, o);
  GvfMultigridOptions mo;
  mo.mu = 0.2;
  mo.tolerance = 1e-6;
  mo.max_cycles = 40;
  int cycles = 0;
  const GvfField mg = gvf_multigrid(f, mo, &cycles);
  const double scale = std::max(max_abs(ref.u), max_abs(ref.v));
  EXPECT_LE(max_diff(mg.u, ref.u) / scale, 1e-3);
  EXPECT_LE(max_diff(mg.v, ref.v) / scale, 1e-3);
  EXPECT_LE(cycles, 20) << "multigrid should converge in a few V-cycles";
  // A short explicit run is far from the steady state: the test can tell the two apart.
  GvfOptions short_run = o;
  short_run.iterations = 50;
  const GvfField early = gvf_jacobi(f, short_run);
  EXPECT_GT(max_diff(early.u, ref.u) / scale, 1e-2);
}

TEST(Gvf, DefaultTimeStepObeysTheMaximumPrinciple) {
  // With Δt = 1/(4μ + b_max) each update is a convex combination, so |u| never exceeds the
  // largest |f_x| even after many steps, for any μ.
  const Image2f f = test_edge_map(64, 64, 11);
  Image2f fx, fy;
  edge_gradient(f, fx, fy);
  for (double mu : {0.05, 0.2, 1.0}) {
    GvfOptions o;
    o.mu = mu;
    o.iterations = 2000;
    const GvfField g = gvf_jacobi(f, o);
    EXPECT_LE(max_abs(g.u), max_abs(fx) * (1 + 1e-5)) << "mu " << mu;
    EXPECT_LE(max_abs(g.v), max_abs(fy) * (1 + 1e-5)) << "mu " << mu;
    for (float x : g.u.px) ASSERT_TRUE(std::isfinite(x));
  }
}

TEST(Gvf, FieldPointsTowardTheEdgeFromInsideAndOutside) {
  // A disc edge: GVF's capture range means that inside and outside the ring the field points
  // at the ring (Xu & Prince Fig. 3), where the plain gradient ∇f is zero.
  const int n = 96;
  std::vector<float> hu(std::size_t(n) * n);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) hu[std::size_t(y) * n + x] = std::hypot(x - 48.0, y - 48.0) < 25 ? 0.0f : 100.0f;
  const Image2f f = edge_map(hu.data(), n, n, 1, 1, {-150, 150, 1.0});
  const GvfField g = gvf_multigrid(f, {});
  int good = 0, total = 0;
  for (double r : {8.0, 14.0, 35.0, 42.0})
    for (int a = 0; a < 16; ++a) {
      const double t = a * 2 * M_PI / 16, x = 48 + r * std::cos(t), y = 48 + r * std::sin(t);
      const double u = g.u.sample(x, y), v = g.v.sample(x, y);
      const double radial = (u * std::cos(t) + v * std::sin(t)) / (std::hypot(u, v) + 1e-30);
      ++total;
      if ((r < 25 && radial > 0.9) || (r > 25 && radial < -0.9)) ++good;
    }
  EXPECT_EQ(good, total);
}
