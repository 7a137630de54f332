#pragma once
// The byte structure of a DICOM Part-10 file, checked before GDCM reads it: GDCM aborts (an
// assertion in its compatibility reader) or decodes garbage on some truncated files, so every
// declared length up to and including the pixel data must be known to fit first. The walk
// follows the transfer syntax of the file meta (implicit or explicit VR, little or big endian;
// a deflated data set is inflated and walked), into sequences and items of undefined length and
// through the fragments of encapsulated pixel data. Bounded: nesting deeper than 64 levels and
// more than 10⁷ elements are refused. Depends on the standard library and zlib only (fuzzed on
// its own: fuzz/).

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

namespace organsmith {

struct DicomStructure {
  bool complete = false;          ///< every declared length fits; false: `why` says where it does not
  std::string why;                ///< e.g. "is truncated: element (7fe0,0010) needs … bytes but only … remain"
  std::string transfer_syntax;    ///< the meta's (0002,0010), trimmed; empty without one
  bool has_pixel_data = false;
  bool encapsulated = false;      ///< pixel data in fragments (compressed transfer syntaxes)
  std::uint64_t pixel_offset = 0; ///< native pixel data: where its value starts in the file
  std::uint64_t pixel_bytes = 0;  ///< native pixel data: its length
  std::uint64_t fragment_bytes = 0;  ///< encapsulated: the fragments' total length (offset table included)
};

/// Reads `n` bytes at `pos` into `out`; false when they are not all there.
using ByteReader = std::function<bool(std::uint64_t pos, std::size_t n, unsigned char* out)>;

/// Walks a Part-10 byte stream of `size` bytes.
DicomStructure check_dicom_structure(std::uint64_t size, const ByteReader& read);
/// The same over a buffer in memory.
DicomStructure check_dicom_structure(const unsigned char* data, std::size_t size);
/// The same over a file (read piecewise; the pixel data itself is not read).
DicomStructure check_dicom_structure(const std::filesystem::path& file);

}  // namespace organsmith
