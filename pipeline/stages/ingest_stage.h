#pragma once
// The ingest stage: the case's input read (DICOM series, NIfTI, NRRD, MetaImage; pipeline/io),
// its record ingest.json (what was read, its geometry and digest) and each organ's seed resolved
// to LPS mm. Run by `organsmith run` and, through it, by the single-stage commands.

#include "core/progress.h"
#include "core/volume.h"
#include "pipeline/case/case_file.h"
#include "pipeline/io/ingest.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// An organ's seed as the ingest stage resolved it (ingest.json "organs").
struct OrganSeed {
  std::string organ;
  std::optional<Eigen::Vector3d> lps_mm;  ///< none: found automatically or taken from a label map
  std::string source;                     ///< "case file (LPS mm)", "phantom seeds.json", "automatic", …
};

struct IngestStageInputs {
  std::filesystem::path input;              ///< the case's input (the phantom's DICOM for a synthetic case)
  std::vector<OrganSpec> organs;            ///< the case's organs, in order
  const OrganRegistry* registry = nullptr;  ///< required: which organs need a seed
  /// A synthetic case's seeds by organ (seeds.json); null for a scan.
  const std::map<std::string, Eigen::Vector3d>* phantom_seeds = nullptr;
  std::filesystem::path case_file;          ///< named in errors about seeds
};

struct IngestStageResult {
  Volume volume;                 ///< the CT in HU on its grid (LPS mm)
  std::vector<OrganSeed> seeds;  ///< one per organ, in case order
  /// The manifest's record of the input: format, digest_sha256 (of the voxels), grid.
  nlohmann::json input;
};

/// Reads the input, resolves the seeds and writes ingest.json into `staging`. InputError (exit
/// code bad_seed) when a seed lies outside the image.
IngestStageResult ingest_stage(const IngestStageInputs& in, const IngestOptions& options,
                               const std::filesystem::path& staging, Progress& progress);

/// The organ seeds of ingest.json (its reader), for a run that reuses the ingest stage.
std::vector<OrganSeed> read_ingest_seeds(const std::filesystem::path& ingest_json);

}  // namespace organsmith
