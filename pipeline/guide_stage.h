#pragma once
// The guide stage (guidance paths from a run's output directory), shared by `organsmith run`
// and `organsmith guide`. Defined in pipeline/runner.cpp.

#include "physics/paths.h"
#include "pipeline/organ_registry.h"

#include <filesystem>
#include <string>
#include <vector>

namespace organsmith {

struct GuideStageOptions {
  physics::CenterlineOptions centerline;
  physics::IncisionOptions incision;
  physics::DissectionOptions dissection;
  /// Built-in paths to make: "trachea_centerline", "trachea_incision", "gallbladder_dissection".
  /// Empty = every path whose organ the label map holds.
  std::vector<std::string> only;
};

/// Names of the built-in paths, in the order they are made.
const std::vector<std::string>& builtin_path_names();

/// Reads OUT_DIR/labels.nii.gz (else phantom/ground_truth.nii.gz), the organ surfaces in
/// OUT_DIR/meshes/ and, for the liver bed, the liver label (of the label map, else of
/// phantom/ground_truth.nii.gz on the same grid); writes <name>.json and <name>.vtp per path into
/// `dest_dir` (created). Returns the file names written. Throws InputError (exit code 3) when
/// the label map or a needed organ surface is missing.
/// The trachea's and the liver's labels and the organs' surface names come from `registry`.
std::vector<std::string> write_guidance_paths(const std::filesystem::path& out_dir, const std::filesystem::path& dest_dir,
                                              const GuideStageOptions& options, const OrganRegistry& registry);

}  // namespace organsmith
