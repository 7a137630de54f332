// libFuzzer target: the NRRD and MetaImage header checks (pipeline/io/text_header_check.h) on any
// bytes, as a .nrrd and as a .mha file. They must accept or throw organsmith's own errors; never
// crash, hang or allocate what a header announces.
#include "core/errors.h"
#include "pipeline/io/text_header_check.h"

#include <unistd.h>

#include <fstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  static const std::string base = "/dev/shm/organsmith-fuzz-text-" + std::to_string(::getpid());
  const std::int64_t budget = std::int64_t(64) << 20;
  for (const char* ext : {".nrrd", ".mha"}) {
    const std::string path = base + ext;
    {
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
    }
    try {
      if (ext[1] == 'n') organsmith::check_nrrd_file(path, budget);
      else organsmith::check_metaimage_file(path, budget);
    } catch (const organsmith::Error&) {
    }
  }
  return 0;
}
