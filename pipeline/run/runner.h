#pragma once
// The stage runner: runs a case's stages in order into an output directory, skips stages whose
// inputs and options did not change, commits each stage's files atomically, and records
// everything in <out>/manifest.json.

#include "core/progress.h"
#include "pipeline/case/case_file.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace organsmith {

struct RunOptions {
  bool force = false;  ///< rerun every stage even when its fingerprint is unchanged
  std::string until;   ///< stop after this stage (empty = run all); see `stage_names()`
  /// Start at this stage (empty = the first): the stages before it must have run into the output
  /// directory already (their manifest records are taken as they are). This is how the
  /// single-stage commands continue a run (`mesh DIR`, `guide DIR`, `snapshot DIR`).
  std::string from;
  /// A command that made the output directory removes it again when it fails, so that a failed
  /// `segment` leaves nothing (`run` keeps the stages that succeeded, to resume from them).
  bool all_or_nothing = false;
};

/// The stages of `organsmith run`, in order (the phantom stage only runs for input = "phantom").
const std::vector<std::string>& stage_names();

/// What happened to one stage.
struct StageRecord {
  std::string name;
  std::string fingerprint;     ///< SHA-256 of the stage's options and input digests
  bool skipped = false;        ///< true when reused from a previous run
  double seconds = 0.0;
  double peak_rss_mib = 0.0;   ///< resident-set high-water mark during the stage
  nlohmann::json outputs = nlohmann::json::array();  ///< [{path, bytes, sha256}], paths relative to out
};

struct RunSummary {
  std::filesystem::path out_dir;
  std::vector<StageRecord> stages;
  nlohmann::json manifest;
};

/// Runs `c` into c.out_dir. Throws organsmith::Error on failure; files of the failing stage are
/// never left behind (each stage writes into a staging directory that is renamed into place).
RunSummary run_case(const CaseFile& c, const RunOptions& options, Progress& progress);

}  // namespace organsmith
