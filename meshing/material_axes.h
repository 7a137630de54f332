#pragma once
// Material axes of an organ's wall, per element, for laws measured on strips cut along and across
// the organ (thesis §5.1.2: longitudinal and circumferential strips of gallbladder wall). The wall
// normal at an element is the outward normal of the nearest face of the organ's outer surface; the
// longitudinal axis is the organ's long axis (the principal axis of its nodes with the largest
// spread) projected onto the plane normal to it, and circumferential = normal × longitudinal. Where
// the long axis is nearly normal to the wall (the fundus and neck tips, a tube's end caps) the
// second principal axis is projected instead, so every element gets an orthonormal pair.

#include "meshing/solver_model.h"

#include <Eigen/Core>

#include <vector>

namespace organsmith {

struct MaterialAxes {
  Eigen::Vector3d longitudinal, circumferential;  ///< unit, orthogonal, LPS
};

/// Axes of every element of region `region_id`, in element order. Empty when the model has no
/// `<organ>_outer` surface.
std::vector<MaterialAxes> wall_material_axes(const SolverModel& m, std::int32_t region_id);

}  // namespace organsmith
