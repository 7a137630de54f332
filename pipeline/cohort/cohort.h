#pragma once
// Cohorts: one case run over many studies, each in its own process, on this machine (a process
// pool) or on a Slurm cluster (one job array). A cohort file is a CSV table, one row per study:
//
//   id,input,organs,seed_lps_mm.gallbladder,stages.mesh.edge_mm,reference.gallbladder
//   s001,/data/ct/s001,gallbladder trachea,12.5 -40 310,,/data/ref/s001_gb.nii.gz
//
// `id` (a pseudonym: it names the study's folder, its log and its row in the summary) and `input`
// (a DICOM directory or file, a NIfTI/NRRD/MHA file, "phantom", or "pacs://<name>/<StudyUID>" with
// [pacs.<name>] in the shared case) are required. Every other
// column is optional, an empty field meaning "as the shared case says":
//   organs                   the organs to model, separated by spaces or ';'
//   seed_lps_mm.<organ>      "x y z" in mm (DICOM patient coordinates); seed_ijk.<organ> "i j k"
//   reference.<organ>        a reference label map for the summary's Dice (nonzero = organ)
//   <table>.<key>            any case-file option, e.g. phantom.seed, stages.mesh.edge_mm,
//                            ingest.series, materials.gallbladder_wall (TOML value syntax; text
//                            that is not a TOML value is taken as a string)
// Paths in `input` and `reference.*` are relative to the cohort file; paths in other options to
// the shared case file (--case), as in that case file.

#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace organsmith {

/// One study of a cohort, resolved and validated.
struct CohortStudy {
  std::string id;
  int line = 0;                                          ///< its row's line in the cohort file
  std::string case_toml;                                 ///< the study's complete case (shared case + row)
  std::filesystem::path case_origin;                     ///< anchors the case's relative paths
  std::string input;                                     ///< absolute input path, or "phantom"
  std::map<std::string, std::filesystem::path> references;  ///< organ → reference label map
  /// SHA-256 of the case, the input's file sizes and times, the references and the tool version:
  /// a study that completed with the same fingerprint is not run again.
  std::string fingerprint;
};

struct CohortPlan {
  std::filesystem::path cohort_file;   ///< absolute
  std::filesystem::path shared_case;   ///< absolute; empty = the embedded default case
  std::filesystem::path out_dir;       ///< absolute
  std::vector<CohortStudy> studies;
};

/// Reads and validates a cohort file against the shared case (empty = the embedded default).
/// Every study's case is parsed as `run` would parse it. Throws CaseFileError (exit 20) listing
/// every error of every row at once, each with the cohort file's line and column.
CohortPlan load_cohort(const std::filesystem::path& cohort_file, const std::filesystem::path& shared_case,
                       const std::filesystem::path& out_dir);

nlohmann::json to_json(const CohortPlan& plan);
/// The reader of to_json's output (the plan a cohort's tasks run from). InputError naming `file`.
CohortPlan cohort_plan_from_json(const nlohmann::json& j, const std::filesystem::path& file);

/// `text` with every occurrence of the study's input path replaced by "<input>": what a study
/// writes into logs and the summary never holds the path (a folder may be named after a patient).
std::string redact_study_text(const CohortStudy& study, std::string text);

/// What one run of a study's process reports (cohort/status/<id>.json).
struct StudyStatus {
  std::string id;
  int exit_code = -1;
  std::string message;       ///< the error (redacted); empty on success
  double seconds = 0.0;
  std::string fingerprint;
};

nlohmann::json to_json(const StudyStatus& s);
StudyStatus study_status_from_json(const nlohmann::json& j);

/// Runs study `index` of the plan in `plan.out_dir`/<id> (what each cohort task does, in its own
/// process), writes its status file and returns the exit code. Never throws for the study's own
/// failure: that is the status.
int run_cohort_study(const CohortPlan& plan, std::size_t index);

}  // namespace organsmith
