#pragma once
// The airway wall as its tissues: a tube's tetrahedra split into C-shaped cartilage rings and the
// membranous wall (the posterior trachealis and the annular ligaments between the rings), along
// the tube's own centreline. A CT does not show the rings of an adult trachea reliably (they
// calcify late and patchily), so they are laid out from anatomy: ring height, pitch and the arc
// the cartilage covers (data/organs.toml, [trachea] rings, with sources).

#include "core/geometry.h"

#include <cstdint>

namespace organsmith {

/// Ring layout of a tube wall. `pitch_mm` 0 = one wall region (no split).
struct TubeRings {
  double pitch_mm = 0.0;           ///< distance from one ring to the next along the centreline, mm
  double height_mm = 0.0;          ///< ring height along the centreline, mm (< pitch_mm)
  double cartilage_arc_deg = 270;  ///< the anterior arc a ring covers; the posterior rest is membrane
};

/// Region ids of a split tube wall (see meshing/mesh.h for the others).
inline constexpr std::int32_t kRegionTubeCartilage = 4;
inline constexpr std::int32_t kRegionTubeMembrane = 5;

/// Figures of a split, for the organ's notes and tests.
struct TubeSplit {
  std::size_t cartilage_tets = 0, membrane_tets = 0;
  double cartilage_volume_mm3 = 0.0, membrane_volume_mm3 = 0.0;
  double length_mm = 0.0;          ///< extent of the wall along its centreline
  Eigen::Vector3d axis_lps{0, 0, 1};  ///< the centreline's mean direction (pointing superior)
};

/// Gives every tetrahedron of `wall` (LPS mm) kRegionTubeCartilage or kRegionTubeMembrane: the
/// centreline is the wall's volume centroid in 2 mm slabs along its principal axis; a tet whose
/// centroid lies within the posterior arc (360° − cartilage_arc_deg, centred on LPS +y seen from
/// the centreline) or between rings is membrane. Rings start at the cranial end.
TubeSplit split_tube_wall(TetMesh& wall, const TubeRings& rings);

}  // namespace organsmith
