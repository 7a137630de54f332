#pragma once
// A coarse 3-D region of a seeded fluid-filled organ (internal; not installed): the voxels whose
// in-plane smoothed HU lie in the organ's window, opened in-plane so that partial-volume bands
// and thin bridges to neighbours of similar HU are cut, and 3-D connected to the seed. It tells
// the slice-to-slice snake where the organ continues on the next slice (a fundus section that
// moved sideways, a lobe the previous contour does not cover) and gives it its start contour.

#include "core/volume.h"
#include "segmentation/snake.h"

#include <opencv2/core.hpp>

#include <cstdint>
#include <vector>

namespace organsmith::seg {

struct Region3dOptions {
  double lo_hu = 0, hi_hu = 0;       ///< the organ's HU window
  double sigma_mm = 1;               ///< in-plane smoothing before the window test, mm
  double open_mm = 2.5;              ///< in-plane opening radius, mm (at least one pixel)
  double half_width_mm = 60;         ///< working box around the seed, in-plane half-size, mm
  double half_length_mm = 90;        ///< …and along the slices, mm
};

/// The region, held over a box of the volume.
struct Region3d {
  int x0 = 0, y0 = 0, w = 0, h = 0;   ///< in-plane box, pixels
  std::int64_t k0 = 0, k1 = -1;       ///< slices of the box (inclusive)
  std::vector<cv::Mat> mask;          ///< per slice k − k0: CV_8U w × h, 255 = in the region
  bool has(std::int64_t k) const { return k >= k0 && k <= k1; }
  /// Area of the region on slice k, mm² (0 outside the box).
  double area_mm2(std::int64_t k, double sx, double sy) const;
};

/// Grows the region from the seed voxel (i, j, k). Empty (k1 < k0) when the seed's own
/// neighbourhood does not survive the window and the opening.
Region3d grow_region3d(const Volume& vol, std::int64_t si, std::int64_t sj, std::int64_t sk,
                       const Region3dOptions& options);

/// The region's part on slice k that a contour (slice mm) overlaps: every 2-D component of the
/// slice's region touching the contour's interior dilated by `reach_mm`, as one mask (CV_8U over
/// the box); empty when none. `overlap_px` receives the number of interior pixels on the region.
cv::Mat region_under(const Region3d& r, std::int64_t k, const std::vector<Point2>& contour_mm, double sx, double sy,
                     double reach_mm, int* overlap_px = nullptr);

/// Outer outline (slice mm, counter-clockwise in pixel coordinates, through pixel centres) of the
/// largest blob of a box mask; empty when the mask is empty.
std::vector<Point2> mask_outline_mm(const Region3d& r, const cv::Mat& m, double sx, double sy);
/// The same for a mask whose pixel (0, 0) lies at (x0_mm, y0_mm).
std::vector<Point2> mask_outline_mm(const cv::Mat& m, double x0_mm, double y0_mm, double sx, double sy);

}  // namespace organsmith::seg
