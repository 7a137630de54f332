// libFuzzer target: the NIfTI header check (pipeline/io/nifti_check.h) on any bytes, as a .nii and
// as a .nii.gz file. It must accept or throw organsmith's own errors, never crash or hang, and an
// accepted header must describe a volume that fits the memory budget given.
#include "core/errors.h"
#include "pipeline/io/nifti_check.h"

#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  static const std::string base = "/dev/shm/organsmith-fuzz-nifti-" + std::to_string(::getpid());
  const std::int64_t budget = std::int64_t(64) << 20;
  for (const char* ext : {".nii", ".nii.gz"}) {
    const std::string path = base + ext;
    {
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
    }
    try {
      const organsmith::NiftiHeaderFacts f = organsmith::check_nifti_file(path, budget);
      if (f.version == 1) {
        const double bytes = double(f.size_vox[0]) * double(f.size_vox[1]) * double(f.size_vox[2]) * f.bytes_per_voxel;
        if (!(f.size_vox[0] > 0 && f.size_vox[1] > 0 && f.size_vox[2] > 0) || bytes > double(budget)) std::abort();
        for (double s : f.spacing_mm)
          if (!(s > 0.0) || s != s) std::abort();
      }
    } catch (const organsmith::Error&) {
      // refused with a message and a code: what should happen to most inputs
    }
  }
  return 0;
}
