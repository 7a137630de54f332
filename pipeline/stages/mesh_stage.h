#pragma once
// The mesh stage, the one function behind `organsmith run` (its mesh stage, and `mesh DIR`
// through the runner) and `organsmith mesh LABELS --out DIR`: label map → every organ's surfaces,
// walls and tetrahedra, exported with the registry's fitted materials, each organ's load case
// and the gallbladder's liver bed as its fixed set.

#include "core/progress.h"
#include "core/volume.h"
#include "meshing/mesh.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/case/stage_options.h"
#include "pipeline/stages/guide_stage.h"

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace organsmith {

struct MeshStageInputs {
  const LabelMap* labels = nullptr;          ///< required: every organ's label on the CT's grid
  std::filesystem::path labels_file;         ///< named in errors about the labels (they may be in memory)
  std::vector<MeshOrganSpec> organs;         ///< what to mesh, in order (mesh_spec of the registry's organs)
  const OrganRegistry* registry = nullptr;   ///< required: materials and the liver bed's rule
  std::vector<std::string> band_organs;      ///< organs whose material band is written (options.material_band)
  /// The liver bed's sources besides `labels` (the phantom's ground truth, the CT; each asked for
  /// only when a gallbladder is meshed; either may be empty or return null) and its options (the
  /// guide stage's, so that the solver fixes the organ where the dissection path cuts).
  std::function<const LabelMap*()> truth;
  std::function<const Volume*()> ct;
  GuideStageOptions guide;
  /// The probe the INP's indentation step carries (simulate options): place (LPS mm, empty = the
  /// organ's own rule) and depth (0 = the load case's default).
  std::vector<double> probe_lps_mm;
  double probe_depth_mm = 0.0;
};

/// Meshes `in.organs` of `in.labels` with `options` and exports them into `meshes_dir` (created),
/// one folder per organ. Warnings go to the log, each naming its organ. Throws meshing's errors
/// with `in.labels_file` named, and QualityError (exit 61) when options.quality_gate is "enforce"
/// and a gate still fails after the remedies.
OrganMeshes mesh_stage(const MeshStageInputs& in, const MeshStageOptions& options,
                       const std::filesystem::path& meshes_dir, Progress& progress);

}  // namespace organsmith
