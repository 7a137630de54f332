#pragma once
// Private to the viewer: a planar cut through a CT volume and its label map, sampled on a
// square pixel grid in patient coordinates (no VTK here: plain arrays the views turn into images).

#include "core/volume.h"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace organsmith::viewer_detail {

enum class SliceAxis { axial, coronal, sagittal };
std::string slice_axis_name(SliceAxis a);

/// In-plane screen axes (right, up) and plane normal for radiological display: axial seen from
/// the feet (patient's left on the right, anterior up), coronal from the front, sagittal from
/// the patient's left (anterior on the left).
struct SliceFrame {
  Eigen::Vector3d right, up, normal;
};
SliceFrame slice_frame(SliceAxis a);

/// Pixel (x, y) has its centre at centre_lps + right·(s0 + x·pixel_mm) + up·(t0 + y·pixel_mm);
/// row y = 0 is the bottom row.
struct SliceSample {
  SliceAxis axis = SliceAxis::axial;
  SliceFrame frame;
  Eigen::Vector3d centre_lps_mm = Eigen::Vector3d::Zero();
  double pixel_mm = 1.0;
  double s0 = 0, t0 = 0;
  int width = 0, height = 0;
  std::vector<float> hu;             ///< trilinear; NaN outside the volume
  std::vector<std::uint8_t> labels;  ///< nearest voxel; 0 outside (empty when no label map)
};

/// Samples the plane through `centre_lps_mm` perpendicular to `axis`, covering the whole volume.
SliceSample sample_slice(const Volume& ct, const LabelMap* labels, SliceAxis axis, const Eigen::Vector3d& centre_lps_mm);

/// Centroid (LPS mm) of the voxels carrying `label`; false when there are none.
bool label_centroid(const LabelMap& labels, std::uint8_t label, Eigen::Vector3d& centroid_lps_mm);

/// Letter of the patient direction a unit vector points to most: L R P A S I.
char direction_letter(const Eigen::Vector3d& v);

}  // namespace organsmith::viewer_detail
