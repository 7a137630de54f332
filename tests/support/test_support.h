#pragma once
// Helpers shared by the pipeline tests: where the real cases are, scratch directories, and
// running the organsmith CLI as a user would.

#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <string>

namespace organsmith::testing {

/// ../shared/data/real beside the project, or empty when absent (tests then skip).
std::filesystem::path real_data_dir();

/// A fresh, empty directory under the system temp dir, removed when the object dies.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& tag);
  ~ScratchDir();
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& p) const { return path_ / p; }

 private:
  std::filesystem::path path_;
};

/// A small file system of its own (tmpfs of `size_kib`), mounted on a fresh scratch directory and
/// unmounted when the object dies (also when the test fails): a disk that fills up. Mounting needs
/// CAP_SYS_ADMIN (root here and in CI); where it is refused, `mounted()` is false and `why()` says
/// why, for GTEST_SKIP.
class SmallDisk {
 public:
  SmallDisk(const std::string& tag, int size_kib);
  ~SmallDisk();
  SmallDisk(const SmallDisk&) = delete;
  SmallDisk& operator=(const SmallDisk&) = delete;
  bool mounted() const { return mounted_; }
  const std::string& why() const { return why_; }
  const std::filesystem::path& path() const { return dir_.path(); }
  std::filesystem::path operator/(const std::string& p) const { return dir_ / p; }

 private:
  ScratchDir dir_;
  bool mounted_ = false;
  std::string why_;
};

struct CliResult {
  int exit_code = -1;
  std::string output;  ///< stdout and stderr together
};

/// Runs the organsmith executable with `args` (shell-quoted by the caller where needed).
CliResult run_cli(const std::string& args);
/// Runs the organsmith executable with `args` in `cwd` (empty: the current directory) under
/// timeout(1): exit 124 when it ran past `timeout_s` (then killed), 128 + n when signal n ended it.
CliResult run_cli_bounded(const std::string& args, int timeout_s, const std::filesystem::path& cwd = {});
/// The same, returning the exit code; the output goes to `*output` when given.
int run_cli(const std::string& args, std::string* output);

/// Every file under `dir` (recursively), as paths relative to it.
std::size_t count_files(const std::filesystem::path& dir);

/// The whole file as bytes (empty when it cannot be opened).
std::string read_file(const std::filesystem::path& path);

/// `p` in single quotes, for a CLI argument.
std::string quoted(const std::filesystem::path& p);

/// The JSON file `p` (throws when it is not JSON).
nlohmann::json read_json(const std::filesystem::path& p);

/// SHA-256 of every file under `dir` by relative path, leaving out files named `skip`.
std::map<std::string, std::string> file_digests(const std::filesystem::path& dir, const std::string& skip = "");

/// True when a staging folder (".<stage>.staging-<hex>") is anywhere under `dir`.
bool has_staging_leftover(const std::filesystem::path& dir);

/// True when `needle` occurs in any file under `dir`.
bool any_file_contains(const std::filesystem::path& dir, const std::string& needle);

}  // namespace organsmith::testing

#define ORGANSMITH_REQUIRE_REAL_DATA()                                                        \
  do {                                                                                        \
    if (organsmith::testing::real_data_dir().empty())                                         \
      GTEST_SKIP() << "../shared/data/real is absent: the real-CT checks need it (CI has it)"; \
  } while (0)
