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

/// The calibrated law of an organ region ("gallbladder_body", "trachea_wall", …): from
/// OUT/materials.json (the attach stage) when it has the region, else the built-in preset the
/// region is assigned to. Throws InputError when materials.json is malformed or no law exists.
struct OutputRegionLaw {
  Material material;
  physics::ModelOptions options;
  std::string preset_id;     ///< the preset it came from (as materials.json records it)
  bool from_output = false;  ///< true: read from OUT/materials.json
};
OutputRegionLaw output_region_law(const std::filesystem::path& out, const std::string& region, const OrganRegistry& registry);

/// materials.json (the attach stage) as its one reader gives it: each region's law, or what is
/// wrong with the region's entry.
struct MaterialsFile {
  std::filesystem::path source;                       ///< the file (named in errors)
  std::map<std::string, OutputRegionLaw> regions;     ///< by region name
  std::map<std::string, std::string> malformed;       ///< region → what is wrong with its entry
};
/// Reads materials.json's text (`source` names it); throws InputError when the text is not JSON.
MaterialsFile materials_from_text(const std::string& text, const std::filesystem::path& source);
/// OUT/materials.json through that reader: nothing when the file is absent.
std::optional<MaterialsFile> read_materials(const std::filesystem::path& out);
/// The law of `region`: from `materials` when it has the region (InputError when its entry is
/// malformed), else the built-in preset the registry assigns (InputError when there is none).
OutputRegionLaw output_region_law(const MaterialsFile* materials, const std::string& region, const OrganRegistry& registry,
                                  const std::filesystem::path& materials_path);

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
