#pragma once
// The model a run builds stage by stage in memory (DESIGN: "Model"): each stage takes what the
// stages before it made from here and adds its own part. A stage reused from an earlier run
// leaves its part empty, and the stage after it reads that stage's files through their readers
// (resume and the single-stage commands); no stage reads another's files while they are here.

#include "core/volume.h"
#include "core/geometry.h"
#include "meshing/mesh.h"
#include "pipeline/review/output_scene.h"
#include "pipeline/stages/ingest_stage.h"

#include <Eigen/Core>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {


struct RunModel {
  std::optional<Volume> ct;                     ///< ingest: the CT in HU on its grid (LPS mm)
  std::optional<std::vector<OrganSeed>> seeds;  ///< ingest: one per organ of the case, in case order
  std::optional<LabelMap> labels;               ///< segment: every organ's label on the CT's grid
  std::optional<OrganMeshes> meshes;            ///< mesh: per organ, surfaces and tetrahedra with regions (LPS mm)
  /// phantom: the synthetic case's ground truth (the grid as ground_truth.nii.gz holds it) and
  /// its organ seeds (seeds.json).
  std::optional<LabelMap> phantom_truth;
  std::optional<std::map<std::string, Eigen::Vector3d>> phantom_seeds;
  std::optional<std::vector<ContourStack>> contours;  ///< segment: as contours_<organ>.json hold them
  std::optional<MaterialsFile> materials;             ///< attach: materials.json, through its reader
  std::optional<std::vector<Polyline>> paths;         ///< guide: as paths/<name>.json hold them
};

}  // namespace organsmith
