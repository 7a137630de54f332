#pragma once
// Internal to meshing/: the pieces the CGAL translation units expose to the orchestration in
// mesh.cpp, in core types only (no CGAL here, so that only the .cpp files that need CGAL pay
// for its headers). Coordinates are in the grid frame: q = diag(spacing) · (i, j, k) in mm,
// axis-aligned with the voxel grid; mesh.cpp maps them to LPS at the end (a rigid motion, so
// lengths, angles and orientation are unchanged).

#include "core/geometry.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace organsmith::meshing_detail {

/// A scalar field on a regular axis-aligned grid in the grid frame (mm), sampled trilinearly.
struct Field3 {
  std::array<std::int64_t, 3> n{0, 0, 0};
  Eigen::Vector3d h{1, 1, 1};       ///< sample spacing (mm)
  Eigen::Vector3d origin{0, 0, 0};  ///< position of sample (0, 0, 0) (mm, grid frame)
  std::vector<float> v;             ///< n0 * n1 * n2 values, first axis fastest
  float outside = 0.0f;             ///< value returned outside the grid

  std::int64_t index(std::int64_t i, std::int64_t j, std::int64_t k) const { return i + n[0] * (j + n[1] * k); }
  double sample(const Eigen::Vector3d& q) const;
  Eigen::Vector3d upper() const { return origin + h.cwiseProduct(Eigen::Vector3d(double(n[0] - 1), double(n[1] - 1), double(n[2] - 1))); }
};

/// Axis-aligned box in the grid frame (mm).
struct Box {
  Eigen::Vector3d lo, hi;
};

/// Labels a point (grid frame mm): 0 outside, > 0 the subdomain (region) it lies in.
using LabelFunction = std::function<int(const Eigen::Vector3d&)>;

/// Mesh_3 refinement criteria (mm, degrees).
struct Mesh3Criteria {
  double facet_size_mm = 1.5;
  double facet_distance_mm = 0.1;
  double facet_angle_deg = 30.0;
  double cell_size_mm = 0.0;          ///< 0 = surface only (no cell refinement)
  double cell_radius_edge = 0.0;      ///< 0 = none
  double edge_size_mm = 0.0;          ///< protection of sharp features (polyhedral domains)
  double odt_seconds = 0.0;           ///< > 0: ODT smoothing for at most this long (tets)
  double perturb_bound_deg = 0.0;     ///< > 0: sliver perturbation towards this dihedral angle (tets)
  double exude_bound_deg = 0.0;       ///< > 0: sliver exudation towards this dihedral angle (tets)
  double optimiser_seconds = 30.0;    ///< time limit of perturbation and exudation each (0 = none)
  std::size_t max_vertices = 0;       ///< refinement stops with MeshBudgetExceeded beyond this many vertices; 0 = none
};

/// Mesh_3 refinement reached Mesh3Criteria::max_vertices: the criteria cannot be met at a sane
/// size on this input (a surface with creases the facet distance keeps refining, for one).
struct MeshBudgetExceeded : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Surface between label 0 and the rest of `f` inside `box`, sampled by CGAL Mesh_3
/// (surface criteria only; manifold). Returns a triangle soup with shared vertices;
/// orientation is not fixed here. Deterministic (fixed random seed).
SurfaceMesh mesh3_surface(const LabelFunction& f, const Box& box, const Mesh3Criteria& c);

/// Tetrahedra of the nonzero subdomains of `f` (region id = label), positively oriented.
TetMesh mesh3_tets_implicit(const LabelFunction& f, const Box& box, const Mesh3Criteria& c);

/// Tetrahedra inside a closed, outward-oriented surface (region id `region`); edges whose
/// dihedral angle is sharper than `feature_angle_deg` are protected (flat caps stay flat).
TetMesh mesh3_tets_polyhedral(const SurfaceMesh& closed, std::int32_t region, double feature_angle_deg,
                              const Mesh3Criteria& c);

/// Options of `repair_and_remesh`.
struct RemeshParams {
  double target_edge_mm = 1.5;
  int iterations = 6;
  double min_angle_deg = 25.0;     ///< angle improvement works on triangles below this
  double feature_angle_deg = 0.0;  ///< > 0: keep edges sharper than this (cap rims) as constraints
  std::function<void(const char* step, double seconds)> on_step;  ///< optional: wall time of each phase
};

/// The surface pipeline after sampling: keeps the largest component, fills holes, remeshes
/// isotropically to the target edge length (vertices stay on the input surface), improves
/// the smallest angles (flips, collapses, angle smoothing), and orients it outward.
SurfaceMesh repair_and_remesh(const SurfaceMesh& in, const RemeshParams& p, std::vector<std::string>& notes);

/// The wall of a tube from its two surfaces, both closed and cut flat by the same planes
/// (axis, coordinate): the outer surface and the lumen (turned inside out), their caps removed
/// and replaced by the annuli between the rims on each plane (constrained Delaunay, then
/// remeshed to the target edge with the rims and both tubes held). One genus-1 surface, outward.
/// Throws when the surfaces do not join (no caps, rims that cross, a non-manifold result).
SurfaceMesh tube_wall_from_surfaces(const SurfaceMesh& outer, const SurfaceMesh& lumen,
                                    const std::vector<std::pair<int, double>>& planes, const RemeshParams& p);

/// Axis-aligned cut: keeps the part with lo ≤ q[axis] ≤ hi and closes it with flat caps.
SurfaceMesh clip_slab(const SurfaceMesh& in, int axis, double lo, double hi);

}  // namespace organsmith::meshing_detail

namespace organsmith::meshing_detail {

/// Separable Gaussian smoothing of `f` in place; σ per axis in samples (0 = none on that axis).
void gaussian_smooth(Field3& f, const Eigen::Vector3d& sigma_samples);

/// Which side of a boundary `signed_distance` measures.
enum class DistanceSide { both, inside, outside };

/// Signed Euclidean distance (mm) to the boundary of {q : f(q) ≥ iso}, negative inside, on
/// f's own grid (exact distance transform between sample centres, half a sample subtracted
/// so that the zero level sits between inside and outside samples). With `side` inside or
/// outside only that side is measured (one transform instead of two); samples on the other
/// side hold ∓ half a sample, which keeps the sign and the zero level.
Field3 signed_distance(const Field3& f, float iso, DistanceSide side = DistanceSide::both);

/// f resampled trilinearly on a grid of spacing `h_mm` covering [lo, hi].
Field3 resample(const Field3& f, const Box& box, double h_mm);

}  // namespace organsmith::meshing_detail
