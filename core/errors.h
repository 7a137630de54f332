#pragma once
// The error hierarchy. Every error says what was wrong with which input and what to do, and
// carries the process exit code the CLI returns for it (distinct per kind of bad input, so that
// scripts can branch on them).

#include <filesystem>
#include <stdexcept>
#include <string>

namespace organsmith {

/// Process exit codes. Documented in README.md ("Exit codes"); never renumber.
enum class ExitCode : int {
  ok = 0,
  internal = 1,
  usage = 2,               ///< bad command line or option value
  input_not_found = 3,     ///< a named input path does not exist or cannot be read
  no_dicom = 10,           ///< directory empty or without any readable DICOM image
  corrupt_file = 11,       ///< a DICOM file is truncated/corrupt and the series is incomplete
  missing_slice = 12,      ///< a gap in slice positions
  nonuniform_spacing = 13, ///< slice spacing varies by more than the tolerance
  gantry_tilt = 14,        ///< slices not stacked along their normal (tilted gantry)
  wrong_modality = 15,     ///< not CT (allow with --allow-modality)
  too_large = 16,          ///< dimensions exceed the memory budget
  series_not_found = 17,   ///< --series UID names no series in the input
  unsupported_input = 18,  ///< a file format or pixel layout organsmith cannot read
  bad_geometry = 19,       ///< invalid spacing / direction cosines
  case_file = 20,          ///< the case file is malformed or names bad values
  output = 30,             ///< an output could not be written
  cancelled = 40,          ///< the user cancelled
  calibration_data = 21,   ///< calibration/uncertainty data unusable (NaN, too few points, non-monotone stretch)
  mesh_input = 60,         ///< a label map unusable for meshing (empty, organ absent, mask too small)
  mesh_quality = 61,       ///< a mesh failed its quality gate (surface guarantees or tetrahedral quality)
  solver_not_found = 70,   ///< the finite-element solver (CalculiX ccx) is not installed
  solver_failed = 71,      ///< the solver stopped without a converged answer (its message is given)
  cohort_incomplete = 80, ///< a cohort ran to its end but some studies failed (cohort.csv says which and why)
  scheduler = 81,          ///< the batch scheduler (Slurm) is missing, refused the job or could not be reached
  pacs_unreachable = 90,   ///< the PACS did not answer (connection refused, no route, timeout) after the retries
  pacs_refused = 91,       ///< the PACS refused us: wrong user or password, or our AE title / its AE title not accepted
  pacs_not_found = 92,     ///< the study (or --series) is not in the PACS
  pacs_no_ct = 93,         ///< the study holds no CT series
  pacs_transfer = 94,      ///< a transfer was cut off or an instance arrived corrupt, after the retries
  organ_not_found = 50,    ///< segmentation could not find the organ (no label written)
  bad_seed = 51,           ///< a segmentation seed outside the image or not inside the organ
};

/// Base of all organsmith errors. `path` is the offending input (may be empty), `hint` what to
/// do about it. what() returns "<message> [<path>] — <hint>" ready to print.
class Error : public std::runtime_error {
 public:
  Error(ExitCode code, std::string message, std::filesystem::path path = {}, std::string hint = {});
  ExitCode code() const { return code_; }
  const std::string& message() const { return message_; }
  const std::filesystem::path& path() const { return path_; }
  const std::string& hint() const { return hint_; }

 private:
  ExitCode code_;
  std::string message_;
  std::filesystem::path path_;
  std::string hint_;
};

/// Bad command-line or option values.
class UsageError : public Error {
 public:
  explicit UsageError(std::string message, std::string hint = {})
      : Error(ExitCode::usage, std::move(message), {}, std::move(hint)) {}
};

/// Something wrong with an input file or directory (code says what).
class InputError : public Error {
 public:
  using Error::Error;
};

/// Invalid voxel-grid geometry.
class GeometryError : public Error {
 public:
  explicit GeometryError(std::string message, std::filesystem::path path = {}, std::string hint = {})
      : Error(ExitCode::bad_geometry, std::move(message), std::move(path), std::move(hint)) {}
};

/// A case file that cannot be used.
class CaseFileError : public Error {
 public:
  CaseFileError(std::string message, std::filesystem::path path, std::string hint = {})
      : Error(ExitCode::case_file, std::move(message), std::move(path), std::move(hint)) {}
};

/// An output that could not be written.
class OutputError : public Error {
 public:
  OutputError(std::string message, std::filesystem::path path, std::string hint = {})
      : Error(ExitCode::output, std::move(message), std::move(path), std::move(hint)) {}
};

/// Raised by long stages when their Progress reports cancellation.
class Cancelled : public Error {
 public:
  Cancelled() : Error(ExitCode::cancelled, "cancelled") {}
};

}  // namespace organsmith
