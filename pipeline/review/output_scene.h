#pragma once
// What a run left in its output directory, gathered for the viewer: the CT, the label map,
// contours, meshes and paths (used by `organsmith snapshot`, `preview` and the run's snapshot
// stage).

#include "core/material.h"
#include "core/progress.h"
#include "core/volume.h"
#include "meshing/mesh.h"
#include "physics/materials/models.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/review/materials_file.h"
#include "viewer/scene.h"

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// Everything `snapshot` and `preview` draw, read from a run's output directory. Owns the CT and
/// the label map that `scene` points to: not copyable or movable.
struct OutputScene {
  std::optional<Volume> ct;
  std::optional<LabelMap> labels;
  SnapshotScene scene;
  std::vector<std::string> missing;  ///< what was looked for and not found (said in the log)

  OutputScene() = default;
  OutputScene(const OutputScene&) = delete;
  OutputScene& operator=(const OutputScene&) = delete;
};

/// Where to find the CT and labels when not in the usual places, and how much context to draw.
struct LoadFlags {
  std::string ct, labels;
  bool need_ct = true;
  int context_step_vox = 2;  ///< in-plane sampling of the context surfaces (liver, lungs); 0 = none
  /// Results of `organsmith calibrate` / `uncertainty --method mc` kept outside OUT_DIR, drawn as
  /// plots (directories under OUT_DIR holding them are found by themselves).
  std::vector<std::string> calibration_dirs;
  bool plots = true;  ///< build the plots (material laws, Monte Carlo CDFs, calibration fits)
  /// The organ registry of the run; null = the one the directory's manifest names, else the
  /// embedded one.
  const OrganRegistry* registry = nullptr;
  /// What a run holds in memory already, used instead of reading the files (null = read them).
  /// They must outlive the OutputScene.
  const Volume* ct_volume = nullptr;
  const LabelMap* label_map = nullptr;
  const OrganMeshes* meshes = nullptr;  ///< the mesh stage's result, LPS mm
  const LabelMap* phantom_truth = nullptr;              ///< the phantom stage's ground truth
  const std::vector<ContourStack>* contours = nullptr;  ///< the segment stage's, as its files hold them
  const std::vector<Polyline>* paths = nullptr;         ///< the guide stage's, as its files hold them
  const MaterialsFile* materials = nullptr;             ///< the attach stage's materials.json
  /// The running case's name and organs (empty = as the directory's manifest records them).
  std::string case_name;
  std::vector<std::string> organs;
};

/// Fills `os` from the output directory `out`; what is missing is listed in os.missing.
void load_output_scene(const std::filesystem::path& out, const LoadFlags& flags, OutputScene& os,
                       Progress& progress);

}  // namespace organsmith
