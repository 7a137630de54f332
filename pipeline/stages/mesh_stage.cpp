#include "pipeline/stages/mesh_stage.h"

#include "core/errors.h"
#include "meshing/export.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <optional>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

/// Each organ's load case: its registry's, or the pressure / probe the options ask for, with the
/// probe's depth.
std::map<std::string, SolverScenario> scenarios(const MeshStageInputs& in, const MeshStageOptions& mo) {
  std::map<std::string, SolverScenario> out;
  for (const auto& spec : in.organs) {
    SolverScenario sc = default_scenario(spec);
    if (const auto it = mo.pressure_kPa.find(spec.name); it != mo.pressure_kPa.end()) {
      // A pressure asked for: the pressure step (for the gallbladder instead of the probe).
      MeshOrganSpec pressure_spec = spec;
      pressure_spec.load_case = "pressure";
      sc = default_scenario(pressure_spec);
      sc.pressure_kPa = it->second;
    }
    if (std::find(mo.indentation.begin(), mo.indentation.end(), spec.name) != mo.indentation.end()) {
      // The probe asked for (the trachea's anterior wall instead of its airway pressure).
      MeshOrganSpec probe_spec = spec;
      probe_spec.load_case = "indentation";
      sc = default_scenario(probe_spec);
    }
    sc.probe_depth_mm = in.probe_depth_mm;
    out[spec.name] = sc;
  }
  return out;
}

}  // namespace

OrganMeshes mesh_stage(const MeshStageInputs& in, const MeshStageOptions& mo, const fs::path& meshes_dir,
                       Progress& progress) {
  MeshOptions options;
  options.organs = in.organs;
  options.edge_mm = mo.edge_mm;
  options.tet_edge_mm = mo.tet_edge_mm;
  options.tetrahedra = mo.tetrahedra;
  options.max_fold_deg = mo.max_fold_deg;
  // "enforce" (the default): a figure still failing after the remedies stops the run (exit 61);
  // "report": it is a warning and quality.json records it.
  options.enforce_quality = mo.quality_gate == "enforce";
  OrganMeshes meshes;
  try {
    meshes = mesh_organs(*in.labels, options, progress);
  } catch (const Error& e) {  // meshing knows the labels, not their file: name it
    if (!e.path().empty()) throw;
    throw Error(e.code(), e.message(), in.labels_file, e.hint());
  }
  for (const auto& w : meshes.warnings) spdlog::warn("mesh: {}", w);
  for (const auto& organ : meshes.organs) {
    for (const auto& w : organ.warnings) spdlog::warn("mesh: {}", w);  // each names its organ
    for (const auto& f : organ.volume_quality.failures)
      spdlog::warn("mesh: {}: tetrahedral quality gate not met: {}", organ.spec.name, f);
    for (const auto& surf : organ.surfaces)
      for (const auto& f : surf.quality.failures) spdlog::warn("mesh: {}: {}", surf.name, f);
  }

  ExportOptions ex;
  ex.formats = mo.formats;
  ex.ras = mo.ras;
  ex.materials = region_materials(*in.registry);
  ex.quadratic = !mo.linear_tets;
  if (mo.material_band) ex.material_band = region_band_materials(*in.registry, in.band_organs);
  ex.scenarios = scenarios(in, mo);
  if (const auto& p = in.probe_lps_mm; p.size() == 3) ex.boundaries.probe_lps_mm = Eigen::Vector3d(p[0], p[1], p[2]);
  // A wall_body organ's bed (its fixed set) by the guide stage's rule: its bed organ's label,
  // else the CT, else the bed's usual direction.
  for (const auto& organ : meshes.organs)
    if (organ.spec.model == OrganModel::wall_body && !organ.volume.tets.empty()) {
      const OrganInfo& info = in.registry->at(organ.spec.name);
      GuideInputs bed_in;
      bed_in.labels = in.labels;
      if (in.truth) bed_in.truth = in.truth();
      bed_in.ct = in.ct;
      const LiverBedForSolver bed = liver_bed_for_solver(organ.surfaces.front().mesh, bed_in, in.guide, *in.registry, info);
      ex.boundaries.bed_score[organ.spec.name] = bed.score;
      ex.boundaries.bed_source[organ.spec.name] = bed.source;
      spdlog::info("mesh: {} {} bed (fixed in its load case) from the {}", info.name,
                   info.bed_organ.empty() ? "its" : info.bed_organ, bed.source);
    }
  std::vector<std::string> warnings;
  fs::create_directories(meshes_dir);
  export_meshes(meshes, meshes_dir, ex, &warnings);
  for (const auto& w : warnings) spdlog::warn("mesh: {}", w);
  return meshes;
}

}  // namespace organsmith
