#pragma once
// The snapshot stage: the review PNGs of a run's output directory (viewer/snapshot.h), from the
// run's model where it is in memory, and the organs pressed under the simulate stage's probe
// through organsmith's FE model (snapshots/indent_<organ>.png).

#include "core/progress.h"
#include "core/volume.h"
#include "meshing/mesh.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/case/stage_options.h"
#include "pipeline/review/output_scene.h"

#include <filesystem>
#include <string>
#include <vector>

namespace organsmith {

struct SnapshotStageInputs {
  std::filesystem::path out_dir;            ///< the run's directory (what earlier stages wrote)
  std::filesystem::path ct_path;            ///< the run's input (read again when `ct` is null)
  const OrganRegistry* registry = nullptr;  ///< required
  std::string case_name;
  std::vector<std::string> organs;          ///< the case's organs, in order
  /// This run's model in memory, used instead of reading its files (null = read them).
  const Volume* ct = nullptr;
  const LabelMap* labels = nullptr;
  const OrganMeshes* meshes = nullptr;      ///< LPS mm (null when the files are in RAS)
  const LabelMap* phantom_truth = nullptr;
  const std::vector<ContourStack>* contours = nullptr;
  const std::vector<Polyline>* paths = nullptr;
  const MaterialsFile* materials = nullptr;
};

/// Renders `options.views` into `staging`/snapshots/ and presses `options.indent`'s organs.
void snapshot_stage(const SnapshotStageInputs& in, const SnapshotStageOptions& options,
                    const std::filesystem::path& staging, Progress& progress);

}  // namespace organsmith
