#pragma once
// Ingest: any supported CT input → Volume (HU, LPS mm).

#include "core/progress.h"
#include "core/volume.h"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace organsmith {

/// Options of the ingest stage.
struct IngestOptions {
  std::string series_uid;              ///< DICOM series to read; empty = the CT series with the most slices
  bool allow_modality = false;         ///< accept non-CT modalities (with a warning) instead of failing
  double spacing_tolerance = 0.01;     ///< largest relative deviation of a slice step from the median (default 1 %)
  double gap_factor = 1.5;             ///< a slice step above gap_factor × median is a missing slice (default 1.5)
  double tilt_tolerance_deg = 0.1;     ///< largest angle between slice stacking and slice normal (default 0.1°)
  std::int64_t max_memory_bytes = 0;   ///< memory budget for the decoded volume; 0 = 60 % of physical memory
};

/// One DICOM series seen in the input (no patient identifiers).
struct SeriesSummary {
  std::string series_uid;
  std::string modality;
  std::string description;  ///< SeriesDescription (0008,103E)
  int files = 0;            ///< single-frame files, or frames of a multi-frame file
  int rows = 0, columns = 0;
  std::string transfer_syntax;  ///< name, e.g. "JPEG 2000 Lossless"
};

/// What ingest found and did, for the log, `organsmith info` and the manifest.
struct IngestReport {
  std::string format;                 ///< "DICOM", "DICOM multi-frame", "NIfTI", "NRRD", "MetaImage"
  SeriesSummary series;               ///< the series read (DICOM only)
  std::vector<SeriesSummary> other_series;  ///< series seen but not read
  std::vector<std::string> warnings;  ///< skipped files, tolerated oddities
  float hu_min = 0, hu_max = 0;
};

struct IngestResult {
  Volume volume;
  IngestReport report;
};

/// Reads `input`: a DICOM directory (searched recursively), a single DICOM file (multi-frame or
/// one slice), or a NIfTI (.nii, .nii.gz), NRRD (.nrrd, .nhdr) or MetaImage (.mha, .mhd) file.
/// DICOM slices are sorted by their position along the slice normal and rescaled to HU.
/// Throws InputError with a distinct ExitCode for each kind of bad input (see core/errors.h);
/// never writes anything.
IngestResult ingest(const std::filesystem::path& input, const IngestOptions& options, Progress& progress);

/// Digest of pixel values and geometry (never of identifiers): SHA-256 over the grid (size,
/// spacing, origin, direction) and the HU buffer. Identical for identical volumes.
std::string volume_digest(const Volume& volume);

}  // namespace organsmith
