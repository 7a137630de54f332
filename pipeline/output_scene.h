#pragma once
// What a run left in its output directory, gathered for the viewer: the CT, the label map,
// contours, meshes and paths (used by `organsmith snapshot`, `preview` and the run's snapshot
// stage).

#include "core/progress.h"
#include "core/volume.h"
#include "viewer/scene.h"

#include <filesystem>
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
};

/// Fills `os` from the output directory `out`; what is missing is listed in os.missing.
void load_output_scene(const std::filesystem::path& out, const LoadFlags& flags, OutputScene& os,
                       Progress& progress);

}  // namespace organsmith
