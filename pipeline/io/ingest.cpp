#include "pipeline/io/ingest.h"

#include "core/errors.h"
#include "core/sha256.h"
#include "pipeline/io/dicom.h"
#include "pipeline/io/image_io.h"

#include <algorithm>
#include <cmath>

namespace organsmith {

namespace fs = std::filesystem;

IngestResult ingest(const fs::path& input, const IngestOptions& options, Progress& progress) {
  std::error_code ec;
  if (!fs::exists(input, ec))
    throw InputError(ExitCode::input_not_found, "input does not exist", input,
                     "give a DICOM directory, a DICOM file, or a NIfTI/NRRD/MHA file");
  // A device, a pipe or a socket is no scan (reading /dev/zero or a FIFO would never end).
  const auto kind = fs::status(input, ec).type();
  if (kind != fs::file_type::directory && kind != fs::file_type::regular)
    throw InputError(ExitCode::unsupported_input, "the input is neither a file nor a directory (a device, pipe or socket)",
                     input, "give a DICOM directory, a DICOM file, or a NIfTI/NRRD/MHA file");
  IngestResult result;
  if (fs::is_regular_file(input) && is_volume_file_name(input)) {
    progress.report(0.0, "reading volume");
    result.volume = read_volume_file(input, options.max_memory_bytes);
    result.report.format = volume_file_format(input);
    float lo = INFINITY, hi = -INFINITY;
    for (float v : result.volume.hu) lo = std::min(lo, v), hi = std::max(hi, v);
    result.report.hu_min = lo;
    result.report.hu_max = hi;
    progress.report(1.0, "reading volume");
  } else {
    if (fs::is_regular_file(input) && !has_dicom_magic(input))
      throw InputError(ExitCode::unsupported_input, "file is neither DICOM nor a known volume format",
                       input, "give a DICOM directory or file, or a .nii/.nii.gz/.nrrd/.nhdr/.mha/.mhd file");
    result = read_dicom(input, options, progress);
  }
  // Every stage works on axial slices (the snake runs slice by slice across the body's long
  // axis): a series stored as sagittal or coronal slices is reordered, voxel for voxel.
  const std::array<int, 3> order = axial_axis_order(result.volume.grid);
  if (order != std::array<int, 3>{0, 1, 2}) {
    result.volume = permute_axes(result.volume, order);
    result.report.warnings.push_back("stored as non-axial slices (axis order " + std::to_string(order[0]) + "," +
                                     std::to_string(order[1]) + "," + std::to_string(order[2]) +
                                     "): reordered to axial slices, every voxel at its own position");
  }
  return result;
}

std::string volume_digest(const Volume& volume) {
  Sha256 s;
  const ImageGrid& g = volume.grid;
  s.update(g.size_vox.data(), sizeof(g.size_vox));
  s.update(g.spacing_mm.data(), 3 * sizeof(double));
  s.update(g.origin_lps_mm.data(), 3 * sizeof(double));
  s.update(g.direction_lps.data(), 9 * sizeof(double));
  s.update(volume.hu.data(), volume.hu.size() * sizeof(float));
  return s.hex_digest();
}

}  // namespace organsmith
