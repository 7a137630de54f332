#pragma once
// Volumetric image files other than DICOM: NIfTI (.nii, .nii.gz), NRRD (.nrrd, .nhdr) and
// MetaImage (.mha, .mhd). ITK stays inside image_io.cpp.

#include "core/volume.h"

#include <filesystem>
#include <string>

namespace organsmith {

/// True when the file name has an extension read by `read_volume_file`.
bool is_volume_file_name(const std::filesystem::path& path);
/// Human-readable format name for a volume file name ("NIfTI", "NRRD", "MetaImage").
std::string volume_file_format(const std::filesystem::path& path);

/// Reads a scalar volume (values taken as HU; NIfTI scl_slope/inter applied). Geometry is
/// converted to LPS. Throws InputError when the file cannot be read.
/// A NIfTI file's header and data length are checked first (pipeline/io/nifti_check.h) against
/// `max_memory_bytes` (0 = 60 % of physical memory).
Volume read_volume_file(const std::filesystem::path& path, std::int64_t max_memory_bytes = 0);
/// Reads a label map (values cast to uint8; throws when a value is outside 0–255).
LabelMap read_label_map(const std::filesystem::path& path);

/// Sets every background voxel of `labels` to `label` where `source` (any grid in the same patient
/// frame; nearest voxel) carries `label`: an organ taken from another tool's label map. Voxels
/// already labelled are kept. Returns the volume added, ml.
double merge_organ_from_label_map(LabelMap& labels, const LabelMap& source, std::uint8_t label);

/// Writes a volume as float (format from the extension). Not atomic: callers write into a
/// staging directory (see pipeline/output/output_dir.h).
void write_volume_file(const Volume& volume, const std::filesystem::path& path);
/// Writes a label map as uint8 (format from the extension; .nii.gz for stage outputs).
void write_label_map(const LabelMap& labels, const std::filesystem::path& path);

/// The grid that read_label_map of `path` would give, from the header alone. A file stores its
/// geometry in single precision (NIfTI), so a map handed on in memory takes the written file's
/// grid: the next stage then sees the same bits whether the run goes straight on or resumes from
/// the file.
ImageGrid read_image_grid(const std::filesystem::path& path);

}  // namespace organsmith
