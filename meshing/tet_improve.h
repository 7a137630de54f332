#pragma once
// Internal to meshing/: local repair of the few tetrahedra that CGAL Mesh_3's optimisers leave
// below the quality gate. Plain C++ on core types.

#include "core/geometry.h"

namespace organsmith::meshing_detail {

struct TetImproveStats {
  int moved_vertices = 0;
  int peeled_tets = 0;
};

/// Moves interior vertices (not on the boundary nor on a region interface) of tetrahedra whose
/// smallest dihedral angle is below `min_dihedral_deg` or whose radius-edge ratio exceeds
/// `max_radius_edge`, to the position of a few candidates (star centroid, pattern search) that
/// most improves the worst tet of their star; then peels failing tets that have two or more
/// faces on the outer boundary (slivers and caps lying flat on the surface). Never inverts a tet.
TetImproveStats improve_tets(TetMesh& mesh, double min_dihedral_deg, double max_radius_edge);

}  // namespace organsmith::meshing_detail
