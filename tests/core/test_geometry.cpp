#include "core/geometry.h"
#include "core/volume.h"

#include <gtest/gtest.h>

using namespace organsmith;

namespace {
// Unit cube [0,1]^3 as 12 outward triangles.
SurfaceMesh unit_cube() {
  SurfaceMesh m;
  for (int c = 0; c < 8; ++c) m.vertices_lps_mm.emplace_back(c & 1, (c >> 1) & 1, (c >> 2) & 1);
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}
}  // namespace

TEST(SurfaceMesh, UnitCubeVolumeAndArea) {
  const SurfaceMesh m = unit_cube();
  EXPECT_NEAR(m.signed_volume_mm3(), 1.0, 1e-12);
  EXPECT_NEAR(m.area_mm2(), 6.0, 1e-12);
  SurfaceMesh flipped = m;
  for (auto& t : flipped.triangles) std::swap(t[1], t[2]);
  EXPECT_NEAR(flipped.signed_volume_mm3(), -1.0, 1e-12);
}

TEST(TetMesh, PositiveOrientationHasPositiveVolume) {
  TetMesh t;
  t.vertices_lps_mm = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  t.tets = {{0, 1, 2, 3}};
  t.region_ids = {1};
  EXPECT_NEAR(t.volume_mm3(), 1.0 / 6.0, 1e-12);
  t.tets = {{0, 2, 1, 3}};
  EXPECT_LT(t.volume_mm3(), 0.0);
}

TEST(Polyline, ArcLength) {
  Polyline p;
  p.points_lps_mm = {{0, 0, 0}, {3, 4, 0}, {3, 4, 12}};
  const auto s = p.arc_length_mm();
  ASSERT_EQ(s.size(), 3u);
  EXPECT_DOUBLE_EQ(s[1], 5.0);
  EXPECT_DOUBLE_EQ(s[2], 17.0);
  p.closed = true;
  EXPECT_DOUBLE_EQ(p.length_mm(), 17.0 + 13.0);
}

TEST(LabelMap, VolumeInMillilitres) {
  LabelMap m;
  m.grid.size_vox = {10, 10, 10};
  m.grid.spacing_mm = {1.0, 2.0, 5.0};
  m.labels.assign(1000, 0);
  for (int a = 0; a < 100; ++a) m.labels[a] = 1;
  EXPECT_EQ(m.count(1), 100);
  EXPECT_NEAR(m.volume_ml(1), 100 * 10.0 / 1000.0, 1e-12);
}
