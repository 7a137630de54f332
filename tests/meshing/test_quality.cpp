// The fold figure of measure_surface: the angle between the normals of two triangles sharing an
// edge, against shapes whose folds are known in closed form — a cube (90° at its edges, 0° across
// its face diagonals) and a subdivided icosahedron on a sphere (fold ≈ edge / radius in radians).

#include "meshing/quality.h"
#include "tests/physics/synthetic_meshes.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace organsmith;

namespace {

SurfaceMesh cube(double side_mm) {
  SurfaceMesh m;
  for (int i = 0; i < 8; ++i) m.vertices_lps_mm.emplace_back(side_mm * (i & 1), side_mm * ((i >> 1) & 1), side_mm * ((i >> 2) & 1));
  // Two outward triangles per face.
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

/// An icosahedron subdivided `levels` times, on the sphere of radius r.
SurfaceMesh icosphere(double r, int levels) {
  SurfaceMesh m = organsmith::physics::testing::unit_icosphere(levels);
  for (auto& v : m.vertices_lps_mm) v *= r;
  return m;
}

}  // namespace

TEST(SurfaceFolds, ACubeFoldsNinetyDegreesAndFailsTheGate) {
  SurfaceGuarantees g;
  g.max_fold_deg = 60.0;
  const SurfaceQuality q = measure_surface(cube(10.0), 0.0, g);
  EXPECT_NEAR(q.fold_max_deg, 90.0, 1e-9);
  EXPECT_EQ(q.folds_above_limit, 12) << "the cube's 12 edges; its 6 face diagonals are flat";
  ASSERT_FALSE(q.ok());
  EXPECT_NE(q.failures.back().find("12 edges folded beyond 60°"), std::string::npos) << q.failures.back();
  // Not asked for: measured, not a failure.
  EXPECT_TRUE(measure_surface(cube(10.0), 0.0).ok());
}

TEST(SurfaceFolds, ASphereFoldsAboutEdgeOverRadius) {
  SurfaceGuarantees g;
  g.max_fold_deg = 60.0;
  for (int levels : {1, 2, 3}) {
    SCOPED_TRACE(levels);
    const SurfaceMesh s = icosphere(15.0, levels);
    double edge_max = 0;
    for (const auto& f : s.triangles)
      for (int e = 0; e < 3; ++e) edge_max = std::max(edge_max, (s.vertices_lps_mm[f[e]] - s.vertices_lps_mm[f[(e + 1) % 3]]).norm());
    const SurfaceQuality q = measure_surface(s, 0.0, g);
    // Two faces of a sphere sharing an edge of length ≤ h: their normals turn by at most the arc
    // between the faces' centroids, below 2 h / (√3 r) for equilateral-ish faces.
    EXPECT_GT(q.fold_max_deg, 0.0);
    EXPECT_LT(q.fold_max_deg, 2 * edge_max / (std::sqrt(3.0) * 15.0) * 180 / M_PI);
    EXPECT_LE(q.fold_p99_deg, q.fold_max_deg);
    EXPECT_TRUE(q.ok()) << (q.failures.empty() ? "" : q.failures.front());
  }
}
