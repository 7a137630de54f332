#pragma once
// Case files (TOML): what to read, which organs to model with which seeds, stage options.
// The full reference is in README.md ("Case file").

#include "pipeline/io/ingest.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/phantom/phantom.h"
#include "pipeline/case/stage_options.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// One organ to model and where to start looking for it.
struct OrganSpec {
  std::string name;                          ///< an organ of the registry with a mesh model
  std::optional<Eigen::Vector3d> seed_lps_mm; ///< seed in DICOM patient coordinates, mm
  std::optional<Eigen::Vector3d> seed_ijk;    ///< or a seed as a voxel index (converted once the grid is known)
  /// Take the organ from this label map (voxels of its registry label) instead of segmenting it;
  /// "phantom" = the synthesized phantom's ground truth. Empty: the segment stage finds it.
  std::filesystem::path label_map;
};

/// `input = "pacs://<name>/<StudyInstanceUID>"`: the study is pulled from the PACS of the case's
/// [pacs.<name>] table into its cache before ingest (pacs/pacs.h); `input` is then its cache folder.
struct PacsSource {
  std::string name;                      ///< the [pacs.<name>] table
  std::string url;                       ///< http(s)://…/dicom-web or dicom://AET@host:port
  std::string calling_aet = "ORGANSMITH";
  std::filesystem::path ca_file;
  std::filesystem::path cache_dir;       ///< default $XDG_CACHE_HOME/organsmith/pacs (~/.cache/…)
  double timeout_s = 60;
  int retries = 3;
  int move_port = 0;                     ///< DIMSE: C-MOVE to our C-STORE SCP on this port (0 = C-GET)
  std::string study_uid;
};

/// A parsed and validated case.
struct CaseFile {
  std::filesystem::path source;   ///< the file it came from; empty for the embedded default
  std::string name = "case";
  bool synthesize_phantom = false; ///< input = "phantom"
  std::filesystem::path input;     ///< absolute input path (when not synthesizing)
  std::optional<PacsSource> pacs;  ///< input names a PACS study (input = its cache folder)
  PhantomOptions phantom;
  IngestOptions ingest;
  std::vector<OrganSpec> organs;
  /// The organ registry: the embedded one, with the case's own registry file applied.
  OrganRegistry registry = builtin_organ_registry();
  std::filesystem::path registry_file;  ///< [case] organs: the case's registry file (empty = none)
  std::string registry_toml;            ///< its text (for the segment stage's presets)
  /// [materials]: region → preset id or absolute params.json path, already applied to `registry`.
  std::map<std::string, std::string> material_overrides;
  std::filesystem::path out_dir = "out";
  /// [stages.<stage>]: every stage's typed options (defaults where the case says nothing).
  StageOptions stages;
  /// [stages.segment.presets] re-serialised as TOML (organ tables overriding data/organs.toml;
  /// validated on load); empty when the case has none.
  std::string segment_presets_toml;
  /// The same presets as JSON, for the manifest and the segment stage's fingerprint.
  nlohmann::json segment_presets = nlohmann::json::object();
};

/// One stage's resolved options as JSON ("segment": its presets), for the manifest and the
/// stage's fingerprint.
nlohmann::json stage_json(const CaseFile& c, const std::string& stage);

/// The embedded default case followed by every stage option with its default and unit (what
/// `organsmith run --print-default-case` prints; it parses back to the default case).
std::string default_case_with_options_text();

/// Parses a case file. Relative paths in it are taken relative to the file's directory.
/// Throws CaseFileError naming the file, line and key on any mistake (unknown keys included).
CaseFile load_case_file(const std::filesystem::path& path);
/// Parses case text; `origin` names it in errors and anchors relative paths.
CaseFile parse_case(const std::string& toml_text, const std::filesystem::path& origin);
/// Sets the case's segmentation preset overrides (TOML, one table per organ, as
/// `organsmith segment --presets` takes them); CaseFileError naming `origin` on a bad key.
void set_segment_presets(CaseFile& c, const std::string& toml_text, const std::filesystem::path& origin);
/// The embedded default case (data/default_case.toml).
CaseFile default_case();
/// The embedded default case's text.
const std::string& default_case_text();

/// The case as resolved options, for the manifest.
nlohmann::json to_json(const CaseFile& c);

/// The case a manifest recorded (the reader of to_json's output, validated like a case file),
/// for commands that continue a run: `mesh DIR`, `guide DIR`, `snapshot DIR`. Throws InputError
/// naming `manifest_file` when it records no usable case.
CaseFile case_from_manifest(const nlohmann::json& manifest, const std::filesystem::path& manifest_file);

/// The case of the run that wrote `dir` (its manifest's), with out_dir = `dir`; nothing when
/// `dir` holds no manifest that records a case (e.g. files copied there by hand).
std::optional<CaseFile> case_of_run(const std::filesystem::path& dir);

}  // namespace organsmith
