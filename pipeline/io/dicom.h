#pragma once
// DICOM reading and writing (GDCM stays inside dicom_read.cpp / dicom_write.cpp).

#include "pipeline/io/ingest.h"

#include <Eigen/Core>

#include <filesystem>
#include <string>

namespace organsmith {

/// Reads the DICOM series chosen by `options` from a directory or a single file.
IngestResult read_dicom(const std::filesystem::path& input, const IngestOptions& options,
                        Progress& progress);

/// True when the file starts with a DICOM preamble ("DICM" at byte 128).
bool has_dicom_magic(const std::filesystem::path& file);

/// Identifiers of a series written by organsmith (all synthetic).
struct DicomSeriesIds {
  std::string uid_seed;            ///< every UID is derived from this string, so output is reproducible
  std::string series_description = "organsmith phantom";
  std::string patient_name = "Phantom^Organsmith";  ///< synthetic, not a person
  std::string patient_id = "PHANTOM";
};

/// Writes `volume` as a CT Image Storage series, one uncompressed file per slice
/// (IM0001.dcm, …), int16 with rescale slope 1 / intercept 0. HU must fit int16.
void write_dicom_series(const Volume& volume, const std::filesystem::path& dir,
                        const DicomSeriesIds& ids, Progress& progress);

}  // namespace organsmith
