#pragma once
// The typed options of each stage of a case ([stages.<stage>] in the case file). Every key is a
// field below; one list of fields per stage (visit_*) serves parsing with range checks, the
// manifest's JSON and `organsmith run --print-default-case`.

#include "pipeline/stages/guide_stage.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace organsmith {

/// [stages.mesh]: surfaces, walls and tetrahedra.
struct MeshStageOptions {
  double edge_mm = 1.5;               ///< target surface edge length, mm (default 1.5)
  /// Edge of the tetrahedral meshes (the solver files and the real-time model), mm; the surfaces
  /// keep edge_mm. 0 = edge_mm. Default 4.5: the phantom's solver models have 10 000 (gallbladder)
  /// and 16 000 (trachea) C3D10 nodes, where CalculiX takes ~0.7–1.2 s per Newton iteration on
  /// 2 cores; at 1.5 mm they had 85 000–90 000 and no run ended within ten minutes (README
  /// "Simulation" has the figures).
  double tet_edge_mm = 4.5;
  /// Wall thickness per organ, mm, e.g. { gallbladder = 3.0 }; an organ not named keeps the
  /// organ registry's wall_mm (default: none named).
  std::map<std::string, double> wall_mm;
  bool tetrahedra = true;             ///< also build tetrahedral meshes (default true)
  std::vector<std::string> formats;   ///< export formats (default: all, see meshing/export.h)
  bool ras = false;                   ///< write RAS instead of LPS coordinates (default false)
  /// "enforce" (default): a mesh still missing a quality gate after meshing's remedies stops the
  /// run with exit 61 naming organ, surface and figure (as `organsmith mesh` does); "report": it is
  /// written with warnings and quality.json says which figure failed (`run --allow-quality-failures`).
  std::string quality_gate = "enforce";
  /// Linear tetrahedra (C3D4 / tet4) in the volume files instead of quadratic ones (default false).
  bool linear_tets = false;
  /// A lumen pressure load step for the organs named, kPa, e.g. { trachea = 1.0 }; for the
  /// gallbladder it replaces the indentation. An organ not named keeps its registry load case.
  std::map<std::string, double> pressure_kPa;
  /// Organs whose load step is the thesis' indentation (a rigid probe bonded to the free surface,
  /// displacement-controlled) instead of their registry's pressure, e.g. {"trachea"}: its anterior
  /// wall halfway between the cuts, both cuts held ([stages.simulate] probe_lps_mm / probe_depth_mm
  /// place and size it). Default {}: each organ's registry load case.
  std::vector<std::string> indentation;
  /// Also write each organ's INP with the P5, P50 and P95 variants of its regions' materials
  /// (meshes/<organ>/band/<organ>.p05.inp, …; physics/materials/material_band.h), and the band in
  /// materials.json (default false).
  bool material_band = false;
  /// Fold gate of an organ's outer surface without cut faces: largest angle between neighbouring
  /// triangles, deg (default 60; 0 = off). A mesh failing it is remeshed smoother (meshing's
  /// remedies); see meshing/README.md.
  double max_fold_deg = 60.0;
  MeshStageOptions();
};

/// [stages.simulate]: the organs' load cases in CalculiX.
struct SimulateStageOptions {
  bool enabled = false;   ///< run the stage in `run` (default false: minutes per organ at 1.5 mm edges)
  std::vector<std::string> organs;  ///< organs to simulate; [] = every organ with a load case (default)
  int threads = 0;        ///< solver threads; 0 = every core (default 0)
  double timeout_s = 0;   ///< stop a solver run after this many seconds; 0 = no limit (default 0)
  /// Also run the material band's variants ([stages.mesh] material_band) and report the organ's
  /// largest displacement and lumen volume change as a band (default false).
  bool band = false;
  /// Where the gallbladder's indentation probe touches, LPS mm ({} = the centre of the free
  /// surface opposite the liver bed). Written into the solver files by the mesh stage.
  std::vector<double> probe_lps_mm;
  /// Depth the probe's step presses to, mm; 0 = a quarter of the organ's thickness under it.
  double probe_depth_mm = 0.0;
};

/// [stages.snapshot]: the review pictures.
struct SnapshotStageOptions {
  int width_px = 1024;  ///< PNG width, pixels (default 1024)
  int height_px = 768;  ///< PNG height, pixels (default 768)
  std::vector<std::string> views = {"organs", "overview", "slices", "tets", "plots"};  ///< which views
  /// Organs pressed by the simulate stage's probe through organsmith's FE model (haptics
  /// --indent's quasi-static press) and drawn deformed: snapshots/indent_<organ>.png. [] = none.
  std::vector<std::string> indent;
};

/// Every stage's options of a case. Segment presets stay TOML (see CaseFile).
struct StageOptions {
  MeshStageOptions mesh;
  GuideStageOptions guide;
  SimulateStageOptions simulate;
  SnapshotStageOptions snapshot;
};

/// The stages that take options in a case file, in run order.
const std::vector<std::string>& configurable_stages();

/// One stage's options as JSON (for the manifest and the stage's fingerprint).
nlohmann::json stage_options_json(const StageOptions& o, const std::string& stage);

/// TOML listing every stage option with its default, unit and allowed range, as comments and
/// values that parse back to the defaults.
std::string describe_stage_options();

/// The key among `valid` nearest to `key` (edit distance), for "did you mean" hints.
std::string nearest_key(const std::string& key, const std::vector<std::string>& valid);

}  // namespace organsmith
