#include "core/errors.h"
#include "core/grid.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

using namespace organsmith;

namespace {

ImageGrid oblique_grid() {
  ImageGrid g;
  g.size_vox = {64, 48, 20};
  g.spacing_mm = {0.7, 0.8, 2.5};
  g.origin_lps_mm = {-120.5, 33.25, -410.0};
  // A rotation about an oblique axis: all nine direction cosines non-trivial.
  g.direction_lps = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  return g;
}

}  // namespace

TEST(ImageGrid, IdentityMapsIndexTimesSpacingPlusOrigin) {
  ImageGrid g;
  g.size_vox = {10, 10, 10};
  g.spacing_mm = {0.5, 0.75, 3.0};
  g.origin_lps_mm = {1, 2, 3};
  const Eigen::Vector3d p = g.index_to_lps_mm({2, 4, 1});
  EXPECT_NEAR(p.x(), 1 + 2 * 0.5, 1e-12);
  EXPECT_NEAR(p.y(), 2 + 4 * 0.75, 1e-12);
  EXPECT_NEAR(p.z(), 3 + 1 * 3.0, 1e-12);
}

TEST(ImageGrid, RoundTripWithObliqueDirections) {
  const ImageGrid g = oblique_grid();
  for (double i : {0.0, 3.5, 63.0})
    for (double j : {0.0, 17.25, 47.0})
      for (double k : {0.0, 9.0, 19.0}) {
        const Eigen::Vector3d ijk(i, j, k);
        const Eigen::Vector3d back = g.lps_mm_to_index(g.index_to_lps_mm(ijk));
        EXPECT_LT((back - ijk).norm(), 1e-9) << i << "," << j << "," << k;
      }
}

TEST(ImageGrid, StepAlongAnAxisMovesAlongItsDirectionBySpacing) {
  const ImageGrid g = oblique_grid();
  for (int a = 0; a < 3; ++a) {
    Eigen::Vector3d step = Eigen::Vector3d::Zero();
    step[a] = 1.0;
    const Eigen::Vector3d d = g.index_to_lps_mm(step) - g.index_to_lps_mm(Eigen::Vector3d::Zero());
    EXPECT_NEAR(d.norm(), g.spacing_mm[a], 1e-12);
    EXPECT_NEAR(d.normalized().dot(g.direction_lps.col(a)), 1.0, 1e-12);
  }
}

TEST(ImageGrid, AffineAgreesWithPointMapAndRasFlipsXY) {
  const ImageGrid g = oblique_grid();
  const Eigen::Vector3d ijk(5, 6, 7);
  const Eigen::Vector4d h = g.index_to_lps_affine() * ijk.homogeneous();
  EXPECT_LT((h.head<3>() - g.index_to_lps_mm(ijk)).norm(), 1e-9);
  const Eigen::Vector4d r = g.index_to_ras_affine() * ijk.homogeneous();
  EXPECT_LT((r.head<3>() - lps_to_ras(g.index_to_lps_mm(ijk))).norm(), 1e-9);
  EXPECT_LT((ras_to_lps(lps_to_ras(ijk)) - ijk).norm(), 1e-15);
}

TEST(ImageGrid, SameGeometryDetectsSmallShifts) {
  ImageGrid a = oblique_grid(), b = oblique_grid();
  EXPECT_TRUE(a.same_geometry(b));
  b.origin_lps_mm.x() += 0.01;
  EXPECT_FALSE(a.same_geometry(b, 1e-3));
  EXPECT_TRUE(a.same_geometry(b, 0.02));
}

TEST(ImageGrid, ValidateRejectsBadGeometry) {
  ImageGrid g = oblique_grid();
  EXPECT_NO_THROW(g.validate());
  g.spacing_mm.z() = 0.0;
  EXPECT_THROW(g.validate(), GeometryError);
  g = oblique_grid();
  g.direction_lps(0, 0) *= 1.5;
  EXPECT_THROW(g.validate(), GeometryError);
}
