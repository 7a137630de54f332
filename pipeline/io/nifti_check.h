#pragma once
// Checking a NIfTI-1 file before ITK reads it: a corrupt header (NaN spacing, a singular sform,
// negative dimensions, a 4-D or complex image, an offset beyond the file, data shorter than the
// header says, a cut-off gzip stream) is refused with a message naming the file and the field,
// and the memory reading it needs is compared with the budget before anything is allocated.

#include <array>
#include <cstdint>
#include <filesystem>

namespace organsmith {

struct NiftiHeaderFacts {
  int version = 1;                               ///< 2: a NIfTI-2 file (not checked here)
  std::array<std::int64_t, 3> size_vox{0, 0, 0};
  std::array<double, 3> spacing_mm{0, 0, 0};
  int bytes_per_voxel = 0;
};

/// Checks `path` (.nii or .nii.gz, either byte order). Reads a .nii.gz through to its end once
/// (to know its stream is whole). Throws InputError with code 11 (truncated or corrupt), 16 (over
/// `max_memory_bytes`; 0 = no limit), 18 (a layout organsmith cannot read) or GeometryError (19).
NiftiHeaderFacts check_nifti_file(const std::filesystem::path& path, std::int64_t max_memory_bytes);

}  // namespace organsmith
