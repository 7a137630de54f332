#pragma once
// Quality figures of surface and tetrahedral meshes, measured with CGAL (Polygon Mesh
// Processing, AABB trees). These are the guarantees meshing promises its users; they are
// computed in `mesh_organs`, written to quality.json and re-checked in the tests.

#include "core/geometry.h"
#include "core/volume.h"

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace organsmith {

/// Thresholds the surfaces must meet (defaults: the project's acceptance criteria).
struct SurfaceGuarantees {
  double edge_tolerance = 0.25;          ///< edges within ±25 % of the target …
  double edge_fraction = 0.90;           ///< … for at least 90 % of them
  double min_angle_deg = 25.0;           ///< smallest triangle angle
  double volume_tolerance = 0.03;        ///< |V_mesh − V_label| / V_label
  /// Largest fold: the angle between the normals of two triangles sharing an edge (0 = not
  /// checked). On a smooth organ a fold of θ needs a radius of curvature of about edge / θ, so a
  /// fold beyond ~60° is a feature the edge length cannot carry: a voxel staircase left on a
  /// coarse scan, which a solver's shell elements buckle at.
  double max_fold_deg = 0.0;
};

struct SurfaceQuality {
  std::int64_t vertices = 0, triangles = 0, components = 0;
  bool closed = false, manifold = false, outward = false, self_intersecting = true;
  std::int64_t degenerate_faces = 0;
  double target_edge_mm = 0.0;
  double edge_min_mm = 0.0, edge_mean_mm = 0.0, edge_max_mm = 0.0;
  double edge_within_tolerance = 0.0;  ///< fraction of edges within ±tolerance of the target
  double angle_min_deg = 0.0, angle_p1_deg = 0.0;  ///< smallest angle; 1st percentile
  double fold_max_deg = 0.0, fold_p99_deg = 0.0;   ///< largest fold between neighbouring triangles; 99th percentile
  std::int64_t folds_above_limit = 0;              ///< edges folded beyond SurfaceGuarantees::max_fold_deg
  double area_mm2 = 0.0, volume_mm3 = 0.0;
  double reference_volume_mm3 = 0.0;  ///< label volume compared against (0 = not compared)
  double volume_error = 0.0;          ///< (V_mesh − V_label) / V_label
  double hd95_mm = -1.0;              ///< symmetric 95th-percentile distance to the label boundary (−1 = not measured)
  double hd95_mesh_to_label_mm = -1.0, hd95_label_to_mesh_mm = -1.0;
  double hd_tolerance_mm = 0.0;       ///< one voxel diagonal
  std::vector<std::string> failures;  ///< guarantees that do not hold, in words

  bool ok() const { return failures.empty(); }
};

/// Topology, orientation, self-intersection, degeneracy, edge-length and angle figures of
/// `mesh` (target edge `target_edge_mm`; 0 skips the edge-length check). Fills `failures`.
SurfaceQuality measure_surface(const SurfaceMesh& mesh, double target_edge_mm,
                               const SurfaceGuarantees& g = {});

/// Adds the comparison with label `value` of `labels` to `q`: volume error against
/// `reference_volume_mm3` (pass the voxel volume that should be enclosed) and the symmetric
/// HD95 between the mesh and the boundary of the label's voxels (faces between a voxel of the
/// label and one that is not, including faces on the image border). `clip_k` restricts the
/// label boundary to slices [k0, k1] (−1 = no restriction), for surfaces cut at slice planes.
void compare_with_label(SurfaceQuality& q, const SurfaceMesh& mesh, const LabelMap& labels,
                        std::uint8_t value, double reference_volume_mm3,
                        const SurfaceGuarantees& g = {}, std::int64_t clip_k0 = -1,
                        std::int64_t clip_k1 = -1);

/// Thresholds of the tetrahedral quality gate.
struct TetGuarantees {
  double min_dihedral_deg = 10.0;
  double max_radius_edge = 2.0;
};

struct TetQuality {
  std::int64_t vertices = 0, tets = 0;
  std::int64_t inverted_or_flat = 0;         ///< tets with volume ≤ 1e-12 × edge³
  double volume_mm3 = 0.0;
  double dihedral_min_deg = 0.0, dihedral_max_deg = 0.0;
  double radius_edge_max = 0.0, radius_edge_mean = 0.0;
  std::int64_t below_min_dihedral = 0, above_max_radius_edge = 0;
  std::vector<std::pair<std::int32_t, double>> region_volumes_mm3;  ///< (region id, volume)
  std::vector<std::string> failures;

  bool ok() const { return failures.empty(); }
};

/// Quality figures of a tetrahedral mesh, checked against `g`.
TetQuality measure_tets(const TetMesh& mesh, const TetGuarantees& g = {});

/// JSON objects with every figure above.
nlohmann::json to_json(const SurfaceQuality& q);
nlohmann::json to_json(const TetQuality& q);

}  // namespace organsmith
