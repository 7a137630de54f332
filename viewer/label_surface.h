#pragma once
// A quick surface of one label of a label map, for views made before (or without) the meshing
// stage. It is a smoothed voxel isosurface, not a simulation mesh: titles say so.

#include "core/geometry.h"
#include "core/volume.h"

#include <cstdint>

namespace organsmith {

struct LabelSurfaceOptions {
  int smoothing_iterations = 20;  ///< windowed-sinc smoothing passes (0 = raw voxel staircase), default 20
  double pass_band = 0.08;        ///< windowed-sinc pass band (smaller = smoother), default 0.08
  int step_vox = 1;               ///< sample every step_vox-th voxel in-plane (≥ 1; 2 for big context organs)
};

/// The boundary of the voxels carrying `label`, triangulated (discrete flying edges), smoothed,
/// in LPS mm, oriented outward. Empty when the label is absent. Deterministic.
SurfaceMesh label_surface(const LabelMap& labels, std::uint8_t label, const LabelSurfaceOptions& options = {});

}  // namespace organsmith
