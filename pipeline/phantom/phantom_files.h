#pragma once
// The phantom on disk: <dir>/dicom/IM0001.dcm…, <dir>/ground_truth.nii.gz, <dir>/seeds.json.

#include "core/progress.h"
#include "pipeline/phantom/phantom.h"

#include <filesystem>

namespace organsmith {

/// Writes `phantom` into `dir` (which must exist and be empty; callers stage it, see output_dir.h).
/// UIDs derive from the options, so the same options give byte-identical files.
void write_phantom_files(const Phantom& phantom, const PhantomOptions& options,
                         const std::filesystem::path& dir, Progress& progress);

/// Reads <dir>/seeds.json back: seed per organ name, LPS mm.
std::map<std::string, Eigen::Vector3d> read_seeds(const std::filesystem::path& seeds_json);

}  // namespace organsmith
