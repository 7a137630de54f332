#pragma once
// Internal to meshing/: local repair of the few tetrahedra that CGAL Mesh_3's optimisers leave
// below the quality gate. Plain C++ on core types.

#include "core/geometry.h"

namespace organsmith::meshing_detail {

struct TetImproveStats {
  int moved_vertices = 0;
  int peeled_tets = 0;
  int flips = 0;  ///< 2-3 and 3-2 flips taken
  int splits = 0;  ///< interior edges split at their midpoint
};

/// Moves interior vertices (boundary and region-interface vertices only tangentially, a tenth of
/// an edge at most, and not on creases) of tetrahedra whose
/// smallest dihedral angle is below `min_dihedral_deg` or whose radius-edge ratio exceeds
/// `max_radius_edge`, to the position of a few candidates (star centroid, pattern search) that
/// most improves the worst tet of their star; flips (2-3, 3-2) inside a region where that
/// raises the worst tet involved, and smooths again; then peels failing tets that have two or more
/// faces on the outer boundary (slivers and caps lying flat on the surface). Never inverts a tet.
TetImproveStats improve_tets(TetMesh& mesh, double min_dihedral_deg, double max_radius_edge);

/// One pass of topological flips over the tets failing the gate: 2-3 (a face shared by two tets
/// of one region becomes an edge with three tets around it) and 3-2 (an interior edge with
/// exactly three tets of one region becomes a face with two), each taken only when all new tets
/// are positively oriented and the worst of them scores better than the worst tet replaced. The
/// union of the replaced tets is unchanged, so are the boundary and the region interfaces.
/// Returns the number of flips.
int flip_tets(TetMesh& mesh, double min_dihedral_deg, double max_radius_edge);

}  // namespace organsmith::meshing_detail
