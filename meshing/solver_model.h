#pragma once
// An organ's tetrahedral mesh as a solver takes it: linear or quadratic tetrahedra, named node
// sets and element-face surfaces for boundary conditions, and the organ's default load case.
// One model feeds every solver writer (INP, FEB, MSH, VTU), so the names and numbering agree.
//
// Node order of a quadratic tetrahedron (CalculiX C3D10, Abaqus, FEBio tet10, VTK 24):
// corners 0–3, then mid-edge nodes on edges 0-1, 1-2, 2-0, 0-3, 1-3, 2-3. Corners are oriented so
// that (x1 − x0) × (x2 − x0) · (x3 − x0) > 0. Faces are numbered as CalculiX's S1–S4:
// {0,1,2}, {0,3,1}, {1,3,2}, {2,3,0}; each face's node order makes its normal point into the
// element, so a positive pressure on it pushes into that element.
//
// Surfaces (names prefixed by the organ):
//   wall_body (gallbladder): <organ>_outer (the organ's boundary), <organ>_lumen (the wall's
//     inner face, where wall meets body; faces of wall elements) and <organ>_<bed organ>_bed (the
//     part of the outer surface against the registry's bed organ, the gallbladder's liver bed:
//     where `bed_score` ≥ 0.5 when the pipeline gives one (bed organ label or CT), else whose
//     outward normal lies within `bed_angle_deg` of `bed_direction_lps`; the largest connected
//     patch).
//   tube (trachea): <organ>_outer, <organ>_lumen, <organ>_cranial and <organ>_caudal (the flat
//     cut faces at the top and bottom of the tube).
//   solid: <organ>_outer.
// Each surface also has a node set <surface>_nodes; each region a node set <region>_nodes.

#include "core/geometry.h"
#include "meshing/mesh.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// The organ's analysis in a nonlinear static step: a fixed surface and either a pressure on
/// another (thesis §5.2.1) or the thesis' indentation (§5.1.2): a rigid flat probe pressed into
/// the free surface along its inward normal, displacement-controlled.
struct SolverScenario {
  std::string fixed_surface;      ///< suffix of the fixed surface ("liver_bed", "cuts"); "" = no step
  bool indentation = false;       ///< the probe instead of a pressure
  std::string pressure_surface;   ///< suffix of the loaded surface ("lumen")
  double pressure_kPa = 0.0;      ///< uniform pressure; positive inflates the lumen
  /// Regions that carry no load in this scenario (the gallbladder body under bile pressure: the
  /// pressure acts on the wall). Written as a *MODEL CHANGE removal in the step.
  std::vector<std::string> inactive_regions;
  /// Indentation depth, mm; 0 = kProbeDepthFraction of the organ's thickness under the probe.
  double probe_depth_mm = 0.0;
};

/// The automatic indentation depth as a fraction of the organ's thickness along the probe.
inline constexpr double kProbeDepthFraction = 0.2;
/// The probe's travel per solver increment, mm (export_solver.cpp says why).
inline constexpr double kProbeIncrementMm = 0.15;

/// The indentation probe on a model: where it touches, along which direction it presses, and
/// the faces it holds (the surface <organ>_probe and node set <organ>_probe_nodes). The probe is
/// a rigid flat disc bonded to the wall under it: every node of those faces moves with it.
struct SolverProbe {
  Eigen::Vector3d point_lps_mm{0, 0, 0};   ///< on the outer surface
  Eigen::Vector3d direction_lps{0, 0, 1};  ///< unit, into the organ (the inward surface normal)
  double diameter_mm = 5.0;
  double contact_area_mm2 = 0.0;           ///< area of the faces it holds
  double thickness_mm = 0.0;               ///< the organ's thickness along the direction from the point
  double requested_offset_mm = 0.0;        ///< distance from a requested point to the surface point used
};

struct SolverModelOptions {
  bool quadratic = true;
  Eigen::Vector3d bed_direction_lps{-0.3, 0.0, 1.0};
  double bed_angle_deg = 60.0;
  /// A wall_body organ's bed where the pipeline knows it (the guide stage's rule: the bed organ's
  /// label, else the CT), by organ name: per point of the organ's surface (LPS mm), a score in
  /// [0, 1], the bed ≥ 0.5; and where the bed came from, for the notes. None: the faces within
  /// `bed_angle_deg` of `bed_direction_lps`.
  std::map<std::string, std::function<double(const Eigen::Vector3d&)>> bed_score;
  std::map<std::string, std::string> bed_source;
  /// wall_body: where the indentation probe touches (snapped to the free outer surface); empty =
  /// the centre of the free surface opposite the liver bed. Its diameter comes from the spec.
  std::optional<Eigen::Vector3d> probe_lps_mm;
  /// tube: place the indentation probe too (its scenario presses it): on the anterior outer wall
  /// halfway between the cuts, or nearest `probe_lps_mm`.
  bool probe_on_tube = false;
};

struct SolverFace {
  std::int32_t tet = 0;   ///< element index (0-based)
  std::int32_t face = 0;  ///< 0–3 = CalculiX S1–S4
};

struct SolverModel {
  std::string organ;
  bool quadratic = true;
  std::vector<Eigen::Vector3d> nodes_lps_mm;      ///< corners first, then mid-edge nodes
  std::vector<std::array<std::int32_t, 10>> elements;  ///< 4 or 10 nodes used (see quadratic)
  std::vector<std::int32_t> region_ids;           ///< per element
  std::map<std::int32_t, std::string> region_names;
  std::map<std::string, std::vector<SolverFace>> surfaces;
  std::map<std::string, std::vector<std::int32_t>> node_sets;   ///< sorted, 0-based
  std::vector<std::string> notes;                 ///< how surfaces were found (for file comments)
  std::optional<SolverProbe> probe;               ///< the indentation probe (wall_body with a liver bed; tube on request)

  int nodes_per_element() const { return quadratic ? 10 : 4; }
  /// Node ids (0-based) of face `f` of element `e`: 3 corners, then (quadratic) the 3 mid-edge
  /// nodes of edges (0,1), (1,2), (2,0) of the face.
  std::vector<std::int32_t> face_nodes(const SolverFace& f) const;
  /// Area vector of a face (mm², pointing out of its element).
  Eigen::Vector3d face_area_out_mm2(const SolverFace& f) const;
};

/// Builds the solver model of one organ. Throws MeshInputError when the organ has no tets or a
/// surface its model needs cannot be found (naming which).
SolverModel build_solver_model(const OrganMesh& organ, const SolverModelOptions& options = {});

/// The default scenario of an organ model, from its spec (organ registry `load_case`):
/// wall_body → liver bed fixed, and the probe (indentation) or `pressure_kPa` in the lumen with
/// the body inactive (pressure); tube → both cut faces fixed, and `pressure_kPa` in the lumen or
/// (indentation) the probe on the anterior wall at mid-length;
/// solid or no load case → none (empty fixed_surface).
SolverScenario default_scenario(const MeshOrganSpec& spec);

/// Places the indentation probe on a model whose surfaces are built (called by
/// build_solver_model): adds the surface <organ>_probe and sets `m.probe`; a note says where.
/// `fixed` names the held surface's suffix: a bed, e.g. "liver_bed" (wall_body: by default the
/// centre of the free surface opposite the bed) or "cuts" (tube: by default the most anterior point
/// of the outer wall halfway between the cuts, pressed posteriorly along its inward normal).
void add_indentation_probe(SolverModel& m, const std::optional<Eigen::Vector3d>& requested_lps_mm, double diameter_mm,
                           const std::string& fixed);

/// The suffix of a wall_body organ's bed surface: "<bed_organ>_bed" ("bed" without a bed organ).
std::string bed_surface_suffix(const MeshOrganSpec& spec);

}  // namespace organsmith
