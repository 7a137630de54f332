#pragma once
// Label map → simulation-ready organ meshes: closed outward surfaces remeshed to a target edge
// length, organ walls as separate simulation bodies, and tetrahedral meshes with region ids,
// every one checked against the guarantees in meshing/quality.h. All coordinates are LPS mm.
//
// How a surface is made (chosen by measurement; see meshing/README.md for the figures): the
// organ's largest connected component, less its one-voxel-thin parts, is band-limited to its
// voxel (Gaussian, σ = 0.8 voxel) and
// interpolated trilinearly; CGAL Mesh_3 samples the iso-surface of that field at the level
// whose enclosed volume equals the label's voxel volume (so the smoothing does not shrink the
// organ), and CGAL Polygon Mesh Processing remeshes it isotropically to the target edge length,
// improves the worst angles, fills holes, keeps the largest component and orients it outward.
// Mesh_3 on the raw labeled image reproduces the voxel staircase instead (see README).

#include "core/geometry.h"
#include "core/progress.h"
#include "core/volume.h"
#include "meshing/quality.h"
#include "meshing/tube_regions.h"

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace organsmith {

/// How an organ is turned into simulation bodies.
enum class OrganModel {
  solid,      ///< one closed surface and one tetrahedral region
  wall_body,  ///< gallbladder: a wall layer of `wall_mm` inside the surface plus the body (thesis §5.1.1)
  tube,       ///< trachea: the label is the lumen; a tube wall of `wall_mm` around it, ends cut flat (§5.2)
};

/// One organ to mesh: its name, the label value it carries in the label map, and its model.
struct MeshOrganSpec {
  std::string name;
  std::uint8_t label = 0;
  OrganModel model = OrganModel::solid;
  double wall_mm = 0.0;  ///< wall thickness for wall_body and tube (mm); ignored for solid
  /// tube: the wall as cartilage rings and membrane (regions <name>_cartilage, <name>_membrane);
  /// pitch 0 = one region <name>_wall.
  TubeRings rings;
  /// The organ's default load case in the solver files (organ registry `load_case`):
  /// "indentation" (wall_body: the thesis' 5 mm probe, §5.1.2), "pressure" (lumen pressure), or ""
  /// (none).
  std::string load_case;
  double pressure_kPa = 0.0;       ///< lumen pressure of the pressure load case, kPa
  double probe_diameter_mm = 5.0;  ///< diameter of the indentation probe, mm
  /// wall_body: the organ it lies against (organ registry `bed_organ`); its fixed surface is
  /// <name>_<bed_organ>_bed (<name>_bed when "").
  std::string bed_organ;
};

/// Options of `mesh_organs`.
struct MeshOptions {
  /// The organs to mesh. Meshing knows no organ by itself: the pipeline takes them from the organ
  /// registry (data/organs.toml, `mesh_spec`).
  std::vector<MeshOrganSpec> organs;
  double edge_mm = 1.5;              ///< target surface edge length (mm), default 1.5
  /// Gaussian σ of the mask before iso-surfacing, in voxels of each axis: detail finer than the
  /// voxel is the label's staircase. 0.8 keeps 4 % of the amplitude at the voxels' shortest
  /// wavelength (two voxels: exp(−2π²σ²/λ²)); 0.6 capped at 1.5 mm, the former default, kept
  /// 17 % (29 % on 3 mm voxels) and left creases the fold gate caught (meshing/README.md
  /// "Smooth by design").
  double smoothing_sigma_vox = 0.8;
  double max_smoothing_sigma_mm = 3.0;  ///< cap on σ along thick-slice axes (mm; was 1.5)
  /// Drop the label's voxels one voxel thin along an axis (neither neighbour inside: a plate one
  /// slice thick past both neighbouring sections, a spur one pixel wide) before the surface: no
  /// smooth surface at the grid's resolution carries them. Reported in the organ's warnings. A
  /// label half or more of which is that thin (an organ found on one slice) is refused
  /// (MeshInputError).
  bool drop_thin_voxels = true;
  int remesh_iterations = 6;         ///< isotropic remeshing iterations
  bool tetrahedra = true;            ///< also build tetrahedral meshes
  /// Edge of the tetrahedral meshes (mm; 0 = edge_mm): their boundary facets and cells. The
  /// surfaces keep edge_mm; the volume files are what solvers and the real-time model factor, and
  /// their cost grows with the node count (see the simulate stage's figures in the README).
  double tet_edge_mm = 0.0;
  double min_dihedral_deg = 10.0;    ///< quality gate: every tet's smallest dihedral angle (deg)
  double max_radius_edge = 2.0;      ///< quality gate: every tet's circumradius / shortest edge
  /// Quality gate of an organ's own closed boundary without cut faces (not tubes, not inner
  /// walls): the largest fold between neighbouring triangles (deg; 0 = not checked). See
  /// SurfaceGuarantees::max_fold_deg. On by default since the surface is band-limited to the
  /// voxel and one-voxel-thin parts are dropped: over the real sweep the gallbladder's outer
  /// surface folds by 24–43° (meshing/README.md).
  double max_fold_deg = 60.0;
  /// Smooth every axis by smoothing_sigma_vox × the coarsest spacing (a remedy): a
  /// label map's shape is known to its coarsest voxel, so finer axes otherwise keep plates and
  /// steps thinner than it (a 1 mm-thick last section on 3 mm pixels).
  bool smoothing_isotropic = false;
  bool enforce_quality = true;       ///< throw MeshQualityError when a gate fails (else only report)
  int quality_remedies = 6;          ///< an organ failing a gate is meshed again this many times at most: smoother, finer, both, smoother at a 1.25× edge, smoother isotropically, smoother still
  bool skip_absent = true;           ///< an organ absent from the label map is skipped with a warning
};

/// One named triangle surface of an organ ("gallbladder", "gallbladder_wall_inner",
/// "trachea_wall", "trachea_lumen") and its measured quality.
struct NamedSurface {
  std::string name;
  SurfaceMesh mesh;
  SurfaceQuality quality;
};

/// One timed step of meshing an organ: wall-clock seconds since `mesh_organs` started (the
/// steps of one organ overlap where they run side by side). For benchmarks; not exported.
struct MeshStepTime {
  std::string step;
  double start_s = 0.0, end_s = 0.0;
};

/// Everything built for one organ.
struct OrganMesh {
  MeshOrganSpec spec;
  std::vector<NamedSurface> surfaces;      ///< first: the organ's outer surface
  TetMesh volume;                          ///< empty when tetrahedra are off
  std::map<std::int32_t, std::string> region_names;  ///< tet region id → name ("gallbladder_wall", …)
  TetQuality volume_quality;
  double label_volume_mm3 = 0.0;           ///< voxel volume of the meshed component (and capped slab)
  double dropped_volume_mm3 = 0.0;         ///< voxels not meshed: outside the largest component, or one voxel thin
  double voxel_diagonal_mm = 0.0;
  std::vector<std::string> warnings;       ///< e.g. "touches the image border; capped flat"
  double seconds_surface = 0.0, seconds_tets = 0.0;
  std::vector<MeshStepTime> steps;         ///< per-step timeline, in the order the steps ended
};

struct OrganMeshes {
  std::vector<OrganMesh> organs;
  std::vector<std::string> warnings;  ///< organs skipped and why
};

/// Region ids used in tetrahedral meshes (stable across runs and files).
inline constexpr std::int32_t kRegionGallbladderBody = 1;
inline constexpr std::int32_t kRegionGallbladderWall = 2;
inline constexpr std::int32_t kRegionTracheaWall = 3;
/// Solid organs use kRegionSolidBase + their label value.
inline constexpr std::int32_t kRegionSolidBase = 100;

/// Meshes every organ of `options.organs` found in `labels`. Organs run in parallel (TBB);
/// each one is deterministic: the same label map and options give identical meshes.
/// Throws MeshInputError (naming the organ) for an empty label map, a requested organ absent
/// when `skip_absent` is false, or a mask too small to mesh; MeshQualityError when a quality
/// gate fails and `enforce_quality` is set; Cancelled when `progress` asks to stop.
OrganMeshes mesh_organs(const LabelMap& labels, const MeshOptions& options, Progress& progress);

}  // namespace organsmith

#include "core/errors.h"

namespace organsmith {

/// A label map (or an organ in it) that cannot be meshed (ExitCode::mesh_input): empty, organ
/// absent, a mask too small or too thin for a closed surface at the edge length asked for.
class MeshInputError : public Error {
 public:
  explicit MeshInputError(std::string message, std::string hint = {})
      : Error(ExitCode::mesh_input, std::move(message), {}, std::move(hint)) {}
};

/// A mesh that fails its quality gate (ExitCode::mesh_quality). The message lists every
/// failing figure per surface.
class MeshQualityError : public Error {
 public:
  explicit MeshQualityError(std::string message, std::string hint = {});
};

}  // namespace organsmith
