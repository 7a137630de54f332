#pragma once
// Variants of a scan for the robustness sweep: the CT, its reference label and the seed moved
// through the same change, so a segmentation of the variant can be scored against the equally
// changed reference. Physical changes (slice thickness, field of view, tilt, noise) change the
// voxels; storage changes (RAS order, sagittal slices) keep every voxel at its LPS position.

#include "core/geometry.h"
#include "core/volume.h"
#include "segmentation/segment.h"

#include <Eigen/Core>

#include <cstdint>
#include <string>

namespace organsmith::testing {

struct Scan {
  Volume ct;
  LabelMap ref;                  ///< on ct's grid; nonzero = the organ
  Eigen::Vector3d seed_lps_mm;   ///< a seed inside the organ (unused for the trachea)
};

/// Slices `slice_mm` apart over the same extent: thicker slices average the HU over their
/// thickness (as a scanner reconstructing thick slices does), thinner ones interpolate linearly;
/// the reference is interpolated the same way and thresholded at one half.
Scan resample_slices(const Scan& s, double slice_mm);

/// The field of view cut across the organ: keeps the slices from one end of the volume to the
/// organ's slice at `fraction` of its extent (0 = its lowest-k slice) so that the organ touches
/// the volume's last slice (`keep_low_k`) or its first one; the seed moves to the kept part.
Scan crop_through_organ(const Scan& s, double fraction, bool keep_low_k);

/// The same voxels with the grid's origin moved by `shift_mm` (LPS): the scan, its reference and
/// its seed move together (a scanner placing the same anatomy a fraction of a voxel elsewhere).
Scan shifted_origin(const Scan& s, const Eigen::Vector3d& shift_mm);

/// The same voxels with every spacing times `factor` about the origin (a calibration of ±0.5 %):
/// the anatomy scales with it, the seed too.
Scan scaled_spacing(const Scan& s, double factor);

/// Stored in RAS order: i and j reversed, same voxels at the same positions.
Scan stored_ras(const Scan& s);

/// Stored as sagittal slices (k along the patient's left–right axis), same voxels.
Scan stored_sagittal(const Scan& s);

/// The grid turned by `degrees` about the patient's L axis through the volume's centre (an
/// oblique acquisition): the anatomy, the reference and the seed turn with it.
Scan tilted(const Scan& s, double degrees);

/// Contrast enhancement of an organ: `boost_hu` added where `organ` (a mask on the scan's grid)
/// is, blurred by a Gaussian of `blur_mm` so that its rim is partial volume as in a real scan
/// (portal-venous liver ≈ 100–150 HU against ≈ 55 HU unenhanced).
Scan contrast_enhanced(const Scan& s, const LabelMap& organ, double boost_hu, double blur_mm);

/// Gaussian noise of `sigma_hu` added to every voxel (fixed random seed).
Scan with_noise(const Scan& s, double sigma_hu, unsigned seed);

/// The reference voxel nearest its centre of mass (LPS mm), as a user would click a seed.
Eigen::Vector3d seed_at_centre(const LabelMap& ref);

/// A voxel of the reference near its end along its longest axis (`which` = −1 or +1), at least
/// `depth_mm` inside it where possible: a seed in the neck or the fundus.
Eigen::Vector3d seed_near_end(const Scan& s, int which, double depth_mm);

/// Dice and relative volume error of a label map against the scan's reference (voxels matched
/// through their LPS positions, so any storage order compares).
struct Score {
  double dice = 0, volume_error = 0;
};
Score score_against(const LabelMap& ref, const LabelMap& test, std::uint8_t test_label);

/// Dice between the solid a closed surface encloses and the voxels of `lm` (label `value`; 0 =
/// any nonzero), sampled at 2 × 2 × 2 points per voxel over both's box: how much of the label a
/// smoothed surface keeps (not what the label would score: its staircase is the label's own).
double enclosed_dice(const SurfaceMesh& surface, const LabelMap& lm, std::uint8_t value);

/// An airway reference's own rule applied to the scan's CT: on each slice the reference labels,
/// the air (below air_hu) that is connected in the slice to the reference there (label 1). On
/// a scan whose reference was drawn at that level this is the reference itself; on resampled
/// slices it measures how far the interpolated CT and the interpolated reference disagree.
LabelMap air_under_reference(const Scan& s, float air_hu);

/// The segmentation options the sweeps use: the defaults, with ORGANSMITH_SWEEP_PRESETS (TOML in
/// the form of a case's [segmentation.presets], e.g. "[gallbladder]\nsurface3d = false") applied
/// when set, to compare a preset against the defaults on the same sets without rebuilding.
SegmentOptions sweep_segment_options();

}  // namespace organsmith::testing
