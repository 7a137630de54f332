#pragma once
// The guide stage (guidance paths), shared by `organsmith run` (inputs in memory) and
// `organsmith guide` (inputs read from an output directory).

#include "physics/haptics/paths.h"
#include "pipeline/case/organ_registry.h"

#include "core/geometry.h"
#include "core/volume.h"

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

struct GuideStageOptions {
  physics::CenterlineOptions centerline;
  physics::IncisionOptions incision;
  physics::DissectionOptions dissection;
  /// Paths to make, by name (<organ>_<kind>, OrganRegistry::path_names()). Empty = every path
  /// whose organ the label map holds.
  std::vector<std::string> only;
};


/// What the guide stage reads: the label map, the phantom's ground truth (for the liver bed when
/// the label map has no liver; may be null), the organ surfaces by (organ, surface name), in
/// LPS mm, and the CT. `surface` throws InputError when a surface is missing.
struct GuideInputs {
  const LabelMap* labels = nullptr;
  const LabelMap* truth = nullptr;
  std::function<SurfaceMesh(const std::string& organ, const std::string& surface)> surface;
  /// The CT (HU), for the gallbladder's liver bed when no liver label touches it; called only
  /// then; may be empty or return null (the bed then faces the usual liver direction).
  std::function<const Volume*()> ct;
};

/// GuideInputs read from an output directory (for `guide` on a directory and for resuming): the
/// segmentation, else the phantom's ground truth; surfaces from the exact .vtp, else the .stl;
/// `ras`: the meshes were written in RAS (converted back). Owns what it read.
struct GuideFiles {
  LabelMap labels;
  std::optional<LabelMap> truth;
  std::function<SurfaceMesh(const std::string&, const std::string&)> surface;
  GuideInputs inputs() const { return {&labels, truth ? &*truth : nullptr, surface}; }
};
GuideFiles read_guide_inputs(const std::filesystem::path& out_dir, bool ras = false);

/// A wall_body organ's bed (its registry's `bed_organ`, e.g. the gallbladder's liver bed) as
/// the solver model's fixed set takes it, by the same rule as its dissection path
/// (`physics::liver_bed_score`: the bed organ's label in the label map or the phantom's ground
/// truth, else the CT, else the bed's usual direction): the score at the point of `surface`
/// nearest to a query point (interpolated over its triangle), and the source in words. The
/// solver model and the guide stage so fix the organ where the path cuts.
struct LiverBedForSolver {
  std::function<double(const Eigen::Vector3d&)> score;
  std::string source;
};
LiverBedForSolver liver_bed_for_solver(const SurfaceMesh& surface, const GuideInputs& inputs,
                                       const GuideStageOptions& options, const OrganRegistry& registry,
                                       const OrganInfo& organ);

/// Makes the paths of the registry's organs (`OrganInfo::paths`) that `options` asks for (all
/// whose organ the label map holds by default), writes <name>.json and <name>.vtp per path into
/// `dest_dir` (created) and returns the file names and the paths. Labels, bed organs and surface
/// names come from `registry`.
struct GuidePaths {
  std::vector<std::string> files;  ///< file names written, in order
  std::vector<Polyline> paths;     ///< each path as its <name>.json holds it (its reader's result)
};
GuidePaths write_guidance_paths(const GuideInputs& inputs, const std::filesystem::path& dest_dir,
                                const GuideStageOptions& options, const OrganRegistry& registry);

}  // namespace organsmith
