#pragma once
// An organsmith output directory: the one place that decides what a command may write, replace
// or delete under `--out`. Its manifest.json lists, per stage, every file organsmith wrote there;
// only those files are ever replaced or removed. A file organsmith did not write is never touched.

#include "pipeline/output/read_manifest.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// A fresh staging directory next to `final_path` (same file system, so renames are atomic).
std::filesystem::path make_staging_dir(const std::filesystem::path& final_path);

struct OutputDirOptions {
  /// The command's own inputs (files or directories). The output may be neither inside nor above
  /// any of them, unless the input is a file organsmith wrote into this very directory.
  std::vector<std::filesystem::path> inputs;
  /// The directory is itself the command's input, a run's output that `guide` or `snapshot`
  /// complete: it must exist, and files organsmith did not write may be there (they are still never
  /// replaced). Default false: a non-empty directory needs an organsmith manifest.
  bool in_place = false;
  /// The command name, for messages ("segment", "run", …).
  std::string command = "organsmith";
};

/// One stage's committed files, as recorded in manifest.json: [{path, bytes, sha256}], paths
/// relative to the output directory, sorted.
using OutputList = nlohmann::json;

class OutputDir {
 public:
  /// Checks that `dir` may receive organsmith's outputs and removes staging folders that a killed
  /// run left in it. Throws OutputError (exit 30) when `dir` is a file, lies inside or above an
  /// input, or is a non-empty directory without an organsmith manifest.
  /// Creates nothing: the directory appears with the first committed stage.
  OutputDir(std::filesystem::path dir, OutputDirOptions options);

  const std::filesystem::path& path() const { return dir_; }

  /// The manifest found in the directory when it was opened (an empty object when none).
  const nlohmann::json& previous_manifest() const { return previous_; }

  /// The record of `stage` in the current manifest, or nullptr.
  const nlohmann::json* stage_record(const std::string& stage) const;

  /// Runs `write` into a fresh staging folder inside the directory, then moves its files into
  /// place one by one, replacing the files this stage (or another organsmith stage) wrote before
  /// and removing this stage's earlier files that the new run did not produce. Before anything
  /// moves, a file in the way that organsmith did not write stops the commit (OutputError).
  /// The manifest is rewritten around the move, so a kill at any point leaves every file that
  /// organsmith wrote listed, and the next run may replace it. On any failure the staging folder
  /// is removed and the exception passes on. `record` holds further fields of the stage's
  /// manifest entry (fingerprint, seconds, …); its "outputs" are filled in here.
  OutputList commit(const std::string& stage, const std::function<void(const std::filesystem::path& staging)>& write,
                    nlohmann::json record = nlohmann::json::object());

  /// Records a stage whose outputs were reused from the previous manifest, unchanged.
  void keep(const nlohmann::json& record);

  /// Writes manifest.json: `header` (tool, case, …) with this run's stage records, plus records of
  /// stages from the previous manifest that this run did not touch (their files stay owned).
  void write_manifest(const nlohmann::json& header);

  /// The manifest fields besides the stage records (case, input, …) that commit() writes.
  void set_header(const nlohmann::json& header) { header_ = header; }

  /// The manifest as write_manifest() writes it now.
  nlohmann::json manifest() const { return manifest_json(header_); }

  /// The stage records of this run so far, in order.
  const std::vector<nlohmann::json>& records() const { return records_; }

  /// True when the directory was there before this command.
  bool existed() const { return existed_; }

  /// Removes the directory again when this command created it and it is still empty (a command
  /// that failed before writing anything leaves no empty folder behind).
  void remove_if_unused() const;

 private:
  bool owned(const std::string& relative_path) const;
  nlohmann::json manifest_json(const nlohmann::json& header) const;

  std::filesystem::path dir_;
  OutputDirOptions options_;
  nlohmann::json previous_ = nlohmann::json::object();
  nlohmann::json header_ = nlohmann::json::object();
  std::vector<nlohmann::json> records_;
  bool existed_ = false;
};

/// True when `p` is `root` or lies under it (both made absolute and normalised; symlinks resolved
/// where they exist).
bool path_is_within(const std::filesystem::path& p, const std::filesystem::path& root);

/// Every regular file under `root` with its size and SHA-256, paths relative to `relative_to`.
OutputList list_outputs(const std::filesystem::path& root, const std::filesystem::path& relative_to);

}  // namespace organsmith
