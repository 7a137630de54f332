// Parametric snake: convergence to an edge, the implicit internal step, loop removal.

#include "segmentation/edge_map.h"
#include "segmentation/gvf.h"
#include "segmentation/snake.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace organsmith::seg;

namespace {

// The internal energy Σ α|x'|² + β|x''|² of a closed contour with spacing h (mm).
double internal_energy(const std::vector<Point2>& p, double alpha, double beta) {
  const std::size_t n = p.size();
  const double h = polygon_length(p) / n;
  double e = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Point2& a = p[(i + n - 1) % n];
    const Point2& b = p[i];
    const Point2& c = p[(i + 1) % n];
    e += alpha * (std::pow(c.x - b.x, 2) + std::pow(c.y - b.y, 2)) / (h * h) +
         beta * (std::pow(a.x - 2 * b.x + c.x, 2) + std::pow(a.y - 2 * b.y + c.y, 2)) / (h * h * h * h);
  }
  return e * h;
}

struct DiscScene {
  int n = 120;
  double spacing = 0.8;  // mm
  double radius_mm = 25.0;
  Image2f f, u, v, pressure;
  DiscScene(double noise_hu = 0.0) {
    std::vector<float> hu(std::size_t(n) * n);
    std::mt19937 rng(5);
    std::normal_distribution<float> noise(0.0f, float(noise_hu));
    const double c = (n - 1) / 2.0;
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x)
        hu[std::size_t(y) * n + x] =
            (std::hypot(x - c, y - c) * spacing < radius_mm ? 10.0f : 60.0f) + (noise_hu > 0 ? noise(rng) : 0.0f);
    f = edge_map(hu.data(), n, n, spacing, spacing, {-150, 150, 1.0});
    GvfField g = gvf_multigrid(f, {});
    float mmax = 0;
    for (std::size_t i = 0; i < g.u.px.size(); ++i) mmax = std::max(mmax, std::hypot(g.u.px[i], g.v.px[i]));
    for (std::size_t i = 0; i < g.u.px.size(); ++i) {
      const float s = 1.0f / std::max(std::hypot(g.u.px[i], g.v.px[i]), 0.15f * mmax);
      g.u.px[i] *= s;
      g.v.px[i] *= s;
    }
    u = g.u;
    v = g.v;
    Image2f sm = smooth_slice(hu.data(), n, n, spacing, spacing, 1.0);
    pressure = sm;
    for (float& p : pressure.px) p = std::clamp(std::min(p + 40.0f, 35.0f - p) / 8.0f, -1.0f, 1.0f);
  }
  Point2 centre() const { return {(n - 1) / 2.0 * spacing, (n - 1) / 2.0 * spacing}; }
};

double mean_radius_error(const std::vector<Point2>& p, Point2 c, double r) {
  double e = 0;
  for (const auto& q : p) e += std::abs(std::hypot(q.x - c.x, q.y - c.y) - r);
  return e / p.size();
}

}  // namespace

TEST(Snake, GrowsFromASmallCircleToTheDiscEdge) {
  DiscScene s(8.0);
  SnakeForces forces{&s.u, &s.v, &s.pressure, s.spacing, s.spacing};
  SnakeOptions o;
  const SnakeResult r = evolve_snake(circle(s.centre(), 3.0, 12), forces, o);
  EXPECT_LT(mean_radius_error(r.points, s.centre(), s.radius_mm), 0.5 * s.spacing);
  EXPECT_FALSE(self_intersects(r.points));
  EXPECT_GT(polygon_area(r.points), 0.0);  // counter-clockwise
  // Uniform spacing after reparametrisation (within 10 %).
  const double h = polygon_length(r.points) / r.points.size();
  for (std::size_t i = 0; i < r.points.size(); ++i) {
    const auto& a = r.points[i];
    const auto& b = r.points[(i + 1) % r.points.size()];
    EXPECT_NEAR(std::hypot(b.x - a.x, b.y - a.y), h, 0.1 * h);
  }
}

TEST(Snake, GvfAloneCapturesTheEdgeFromOutside) {
  // No pressure: a large circle well outside the disc is pulled in by the GVF field alone
  // (the capture range that plain ∇f lacks).
  DiscScene s;
  SnakeForces forces{&s.u, &s.v, nullptr, s.spacing, s.spacing};
  SnakeOptions o;
  o.max_iterations = 600;
  const SnakeResult r = evolve_snake(circle(s.centre(), 40.0, 60), forces, o);
  EXPECT_LT(mean_radius_error(r.points, s.centre(), s.radius_mm), 1.0);
}

TEST(Snake, InternalForcesAloneLowerTheInternalEnergy) {
  // Zero external field: each semi-implicit step is a descent step on the internal energy.
  Image2f zero(64, 64, 0.0f);
  SnakeForces forces{&zero, &zero, nullptr, 1.0, 1.0};
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> jitter(-1.5, 1.5);
  std::vector<Point2> p = circle({32, 32}, 15, 90);
  for (auto& q : p) q.x += jitter(rng), q.y += jitter(rng);
  SnakeOptions o;
  o.reparametrise_every = 1000;  // keep the parametrisation fixed so the energies compare
  o.point_spacing_mm = polygon_length(p) / p.size();
  double e_prev = internal_energy(resample_closed(p, int(p.size())), o.alpha, o.beta);
  std::vector<Point2> cur = p;
  for (int step = 0; step < 5; ++step) {
    o.max_iterations = 1;
    cur = evolve_snake(cur, forces, o).points;
    const double e = internal_energy(cur, o.alpha, o.beta);
    EXPECT_LT(e, e_prev) << "step " << step;
    e_prev = e;
  }
}

TEST(Snake, LoopsAreCutOffKeepingTheLargerPart) {
  // A big square with a small twisted loop (a figure-of-eight at one corner).
  std::vector<Point2> p = {{0, 0}, {10, 0}, {10, 10}, {12, 12}, {12, 10}, {10, 12}, {0, 10}};
  ASSERT_TRUE(self_intersects(p));
  remove_loops(p);
  EXPECT_FALSE(self_intersects(p));
  // Kept: the square plus the triangle (10,10)–(11,11)–(10,12) up to the crossing at (11, 11).
  EXPECT_NEAR(std::abs(polygon_area(p)), 111.0, 1e-9);
}

TEST(Snake, ResampleGivesUniformArcLength) {
  std::vector<Point2> p = {{0, 0}, {10, 0}, {10, 1}, {0, 1}};
  const auto q = resample_closed(p, 22);
  ASSERT_EQ(q.size(), 22u);
  for (std::size_t i = 0; i < q.size(); ++i) {
    const auto& a = q[i];
    const auto& b = q[(i + 1) % q.size()];
    EXPECT_LE(std::hypot(b.x - a.x, b.y - a.y), 1.0 + 1e-9);
  }
  EXPECT_NEAR(polygon_length(q), 22.0, 0.3);
}

namespace {

// Outline of the union of two discs (centres a and b, radii ra and rb), n points, counter-
// clockwise: the boundary of a contour that leaked through a gap into a neighbour.
std::vector<Point2> two_discs(Point2 a, double ra, Point2 b, double rb, int n) {
  std::vector<Point2> out;
  // Ray casting from the midpoint of the centres: the union is star-shaped about it here.
  const Point2 m{0.5 * (a.x + b.x), 0.5 * (a.y + b.y)};
  for (int k = 0; k < n; ++k) {
    const double t = 2 * M_PI * k / n, dx = std::cos(t), dy = std::sin(t);
    double far = 0;
    for (const auto& [c, r] : {std::pair{a, ra}, std::pair{b, rb}}) {
      // Largest s with |m + s·d − c| = r.
      const double px = m.x - c.x, py = m.y - c.y, bq = px * dx + py * dy, cq = px * px + py * py - r * r;
      const double disc = bq * bq - cq;
      if (disc >= 0) far = std::max(far, -bq + std::sqrt(disc));
    }
    out.push_back({m.x + far * dx, m.y + far * dy});
  }
  return resample_closed(out, n);
}

double area_inside(const std::vector<Point2>& p, Point2 c, double r) {
  // Fraction of the polygon's vertices within r of c.
  int in = 0;
  for (const auto& q : p) in += std::hypot(q.x - c.x, q.y - c.y) <= r + 1e-6;
  return double(in) / double(p.size());
}

}  // namespace

TEST(Snake, NeckBetweenTwoLobesIsCutKeepingTheStartSide) {
  // Organ of radius 12 mm; neighbour of radius 7 mm whose outline overlaps it through a neck of
  // ≈ 6 mm (neck / neighbour diameter ≈ 0.43 < 0.8).
  const Point2 organ{0, 0}, neighbour{17.5, 0};
  const auto p = two_discs(organ, 12, neighbour, 7, 120);
  ASSERT_FALSE(self_intersects(p));
  for (const auto& [start, kept, radius] :
       {std::tuple{organ, organ, 12.0}, std::tuple{neighbour, neighbour, 7.0}}) {
    const auto cut = cut_necks(p, circle(start, 2.0, 12));
    EXPECT_FALSE(self_intersects(cut));
    const double a = polygon_area(cut);
    EXPECT_GT(a, 0);  // counter-clockwise
    // The kept lobe is the start's disc, closed by the neck chord: its area lies between the
    // disc's area less a cap and the disc's area plus the neck's sliver.
    EXPECT_GT(a, 0.85 * M_PI * radius * radius) << "start at " << start.x;
    EXPECT_LT(a, 1.10 * M_PI * radius * radius) << "start at " << start.x;
    EXPECT_GT(area_inside(cut, kept, radius + 0.5), 0.95);
  }
}

TEST(Snake, ConvexAndShallowlyDentedContoursAreNotCut) {
  // An ellipse of aspect 4 (a long gallbladder section) is convex: no neck, however thin.
  std::vector<Point2> e;
  for (int k = 0; k < 100; ++k) e.push_back({20 * std::cos(2 * M_PI * k / 100), 5 * std::sin(2 * M_PI * k / 100)});
  EXPECT_NEAR(polygon_area(cut_necks(e, circle({0, 0}, 2, 12))), polygon_area(e), 1e-9);
  // Two discs overlapping so much that the dent is 1 mm deep (< min_depth_mm 2): not a neck.
  const auto p = two_discs({0, 0}, 12, {6, 0}, 12, 120);
  EXPECT_NEAR(polygon_area(cut_necks(p, circle({0, 0}, 2, 12))), polygon_area(p), 1e-9);
}
