// libFuzzer target: the DICOM byte-structure check (pipeline/io/dicom_structure.h) on any bytes.
// It must return, never crash, hang or read out of bounds; a verdict of "complete with native
// pixel data" must point inside the input.
#include "pipeline/io/dicom_structure.h"

#include <cstdlib>

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const organsmith::DicomStructure s = organsmith::check_dicom_structure(data, size);
  if (s.complete && s.has_pixel_data && !s.encapsulated && s.transfer_syntax != "1.2.840.10008.1.2.1.99" &&
      s.pixel_offset + s.pixel_bytes > size)
    std::abort();
  if (!s.complete && s.why.empty()) std::abort();
  return 0;
}
