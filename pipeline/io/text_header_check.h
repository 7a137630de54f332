#pragma once
// Checking an NRRD (.nrrd, .nhdr) or MetaImage (.mha, .mhd) file before ITK reads it, as
// nifti_check.h does for NIfTI: sizes, voxel type, spacing and orientation, the data's length
// (a compressed stream inflated through to its end) and the memory reading it needs are checked
// from the text header, and a bad field is refused with a message naming the file and the field.

#include <cstdint>
#include <filesystem>

namespace organsmith {

/// Throws InputError with code 3 (a detached data file is missing), 11 (data shorter than the
/// header says, a cut-off compressed stream), 16 (over `max_memory_bytes`; 0 = no limit), 18 (a
/// layout organsmith cannot read: more than one component, more than 3 dimensions, an unknown
/// voxel type or encoding, a malformed field) or GeometryError (19: a spacing, direction or origin
/// that is not finite, not positive or singular).
void check_nrrd_file(const std::filesystem::path& path, std::int64_t max_memory_bytes);
void check_metaimage_file(const std::filesystem::path& path, std::int64_t max_memory_bytes);

}  // namespace organsmith
