#include "pipeline/io/nifti_check.h"

#include "core/errors.h"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

// NIfTI-1 header layout (nifti1.h): byte offsets of the fields checked here.
constexpr int kHeaderBytes = 348;
constexpr int kDimOffset = 40, kDatatypeOffset = 70, kBitpixOffset = 72, kPixdimOffset = 76;
constexpr int kVoxOffsetOffset = 108, kQformCodeOffset = 252, kSformCodeOffset = 254;
constexpr int kQuaternOffset = 256, kSrowOffset = 280, kMagicOffset = 344, kSclSlopeOffset = 112;

struct Reader {
  const std::uint8_t* p;
  bool swap;
  template <typename T>
  T get(int offset) const {
    std::array<std::uint8_t, sizeof(T)> b;
    std::memcpy(b.data(), p + offset, sizeof(T));
    if (swap) std::reverse(b.begin(), b.end());
    T v;
    std::memcpy(&v, b.data(), sizeof(T));
    return v;
  }
};

/// Bytes per voxel of the datatypes organsmith reads (scalar integers and reals); 0 otherwise.
int datatype_bytes(int datatype) {
  switch (datatype) {
    case 2: case 256: return 1;    // uint8, int8
    case 4: case 512: return 2;    // int16, uint16
    case 8: case 768: case 16: return 4;  // int32, uint32, float32
    case 64: return 8;             // float64
    default: return 0;
  }
}

std::string datatype_name(int datatype) {
  switch (datatype) {
    case 32: return "complex64";
    case 1792: return "complex128";
    case 2048: return "complex256";
    case 128: return "RGB24";
    case 2304: return "RGBA32";
    case 1024: case 1280: return "64-bit integer";
    case 1536: return "float128";
    default: return "datatype " + std::to_string(datatype);
  }
}

}  // namespace

NiftiHeaderFacts check_nifti_file(const fs::path& path, std::int64_t max_memory_bytes) {
  const std::string name = path.filename().string();
  const bool gz = name.size() > 3 && name.compare(name.size() - 3, 3, ".gz") == 0;
  std::array<std::uint8_t, kHeaderBytes> h{};
  std::uint64_t stream_bytes = 0;  // bytes of the (decompressed) file
  if (gz) {
    gzFile f = gzopen(path.c_str(), "rb");
    if (!f) throw InputError(ExitCode::input_not_found, "cannot open the file", path, "check the path and permissions");
    std::uint8_t buf[1 << 16];
    int n = 0;
    bool first = true;
    while ((n = gzread(f, buf, sizeof buf)) > 0) {
      if (first) std::memcpy(h.data(), buf, std::min<std::size_t>(std::size_t(n), kHeaderBytes));
      first = false;
      stream_bytes += std::uint64_t(n);
    }
    int err = Z_OK;
    const char* msg = gzerror(f, &err);
    const std::string what = msg && *msg ? msg : "unexpected end of the stream";  // before gzclose frees it
    const bool complete = n == 0 && err == Z_OK;
    gzclose(f);
    if (!complete)
      throw InputError(ExitCode::corrupt_file, "the compressed stream is cut off or corrupt (" + what + ")", path,
                       "copy the file again; a .nii.gz must hold its whole gzip stream");
  } else {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(ExitCode::input_not_found, "cannot open the file", path, "check the path and permissions");
    in.read(reinterpret_cast<char*>(h.data()), kHeaderBytes);
    std::error_code ec;
    stream_bytes = fs::file_size(path, ec);
  }
  if (stream_bytes < std::uint64_t(kHeaderBytes))
    throw InputError(ExitCode::corrupt_file, "the file is shorter than a NIfTI header (348 bytes)", path,
                     "the file is truncated; copy it again");

  Reader r{h.data(), false};
  NiftiHeaderFacts facts;
  const std::int32_t native = r.get<std::int32_t>(0);
  r.swap = true;
  const std::int32_t swapped = r.get<std::int32_t>(0);
  r.swap = swapped == kHeaderBytes;  // a big-endian header read on this little-endian machine
  if (native != kHeaderBytes && swapped != kHeaderBytes) {
    if ((native == 540 || swapped == 540) && std::memcmp(h.data() + 4, "n+2", 4) == 0) {
      facts.version = 2;  // NIfTI-2: another layout, left to ITK's own checks
      return facts;
    }
    throw InputError(ExitCode::unsupported_input, "not a NIfTI-1 file (the header size field is not 348)", path,
                     "give a NIfTI-1 .nii or .nii.gz file, or a DICOM series");
  }
  if (std::memcmp(h.data() + kMagicOffset, "n+1", 4) != 0)
    throw InputError(ExitCode::unsupported_input, "not a single-file NIfTI-1 image (magic is not \"n+1\")", path,
                     "give a .nii/.nii.gz file (a .hdr/.img pair: convert it, e.g. with ITK-SNAP)");

  const std::int16_t ndim = r.get<std::int16_t>(kDimOffset);
  if (ndim < 1 || ndim > 7)
    throw InputError(ExitCode::unsupported_input, "dim[0] = " + std::to_string(ndim) + " is not 1–7", path,
                     "the header is corrupt");
  std::array<std::int64_t, 3> size{1, 1, 1};
  for (int d = 1; d <= ndim; ++d) {
    const std::int16_t v = r.get<std::int16_t>(kDimOffset + 2 * d);
    if (v < 1)
      throw InputError(ExitCode::unsupported_input, "dim[" + std::to_string(d) + "] = " + std::to_string(v) +
                                                        " (every dimension must be at least 1)",
                       path, "the header is corrupt");
    if (d <= 3) size[std::size_t(d - 1)] = v;
    else if (v > 1)
      throw InputError(ExitCode::unsupported_input,
                       "a " + std::to_string(ndim) + "-D image (dim[" + std::to_string(d) + "] = " + std::to_string(v) + ")",
                       path, "give one 3-D volume (split a time series into its frames first)");
  }
  const int datatype = r.get<std::int16_t>(kDatatypeOffset);
  const int bytes = datatype_bytes(datatype);
  if (bytes == 0)
    throw InputError(ExitCode::unsupported_input, "voxels of type " + datatype_name(datatype) + " are not CT numbers",
                     path, "give a scalar image (integer or real voxels)");
  if (r.get<std::int16_t>(kBitpixOffset) != 8 * bytes)
    throw InputError(ExitCode::unsupported_input, "bitpix does not match the datatype", path, "the header is corrupt");
  for (int d = 1; d <= 3; ++d) {
    const float s = r.get<float>(kPixdimOffset + 4 * d);
    if (!std::isfinite(s) || s <= 0.0f)
      throw GeometryError("pixdim[" + std::to_string(d) + "] = " + std::to_string(s) + " is not a positive spacing", path,
                          "the header's voxel size is corrupt; fix it (e.g. with nibabel) or use the DICOM series");
    facts.spacing_mm[std::size_t(d - 1)] = s;
  }
  if (r.get<std::int16_t>(kQformCodeOffset) > 0) {
    double norm2 = 0;
    for (int k = 0; k < 6; ++k) {
      const float q = r.get<float>(kQuaternOffset + 4 * k);
      if (!std::isfinite(q))
        throw GeometryError("the qform (quaternion or offset) is not finite", path, "the header's orientation is corrupt");
      if (k < 3) norm2 += double(q) * q;
    }
    if (norm2 > 1.0 + 1e-4)  // b² + c² + d² ≤ 1: a = √(1 − b² − c² − d²)
      throw GeometryError("the qform quaternion (b, c, d) is longer than 1", path, "the header's orientation is corrupt");
  }
  {  // Scaling: slope 0 means none (NIfTI-1); otherwise both finite and of CT magnitude.
    const float slope = r.get<float>(kSclSlopeOffset), inter = r.get<float>(kSclSlopeOffset + 4);
    if (slope != 0.0f && !std::isnan(slope) &&
        (!std::isfinite(slope) || std::abs(slope) > 1e4f || !std::isfinite(inter) || std::abs(inter) > 1e6f))
      throw InputError(ExitCode::unsupported_input,
                       "scl_slope " + std::to_string(slope) + " and scl_inter " + std::to_string(inter) +
                           " are not a CT scaling (a slope up to 10⁴, an intercept up to 10⁶)",
                       path, "the header's scaling is corrupt");
  }
  if (r.get<std::int16_t>(kSformCodeOffset) > 0) {
    double m[3][4];
    for (int row = 0; row < 3; ++row)
      for (int c = 0; c < 4; ++c) {
        m[row][c] = r.get<float>(kSrowOffset + 16 * row + 4 * c);
        if (!std::isfinite(m[row][c]))
          throw GeometryError("the sform is not finite", path, "the header's orientation is corrupt");
      }
    const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                       m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if (!(std::abs(det) > 1e-12))
      throw GeometryError("the sform is singular (its axes are not independent)", path, "the header's orientation is corrupt");
  }
  const float vox_offset = r.get<float>(kVoxOffsetOffset);
  if (!std::isfinite(vox_offset) || vox_offset < 352.0f || double(vox_offset) > double(stream_bytes))
    throw InputError(ExitCode::corrupt_file, "vox_offset " + std::to_string(vox_offset) + " lies outside the file", path,
                     "the header is corrupt");
  facts.size_vox = size;
  facts.bytes_per_voxel = bytes;
  const std::uint64_t voxels = std::uint64_t(size[0]) * std::uint64_t(size[1]) * std::uint64_t(size[2]);
  const std::uint64_t data = voxels * std::uint64_t(bytes);
  if (std::uint64_t(vox_offset) + data > stream_bytes)
    throw InputError(ExitCode::corrupt_file,
                     "the header announces " + std::to_string(size[0]) + " × " + std::to_string(size[1]) + " × " +
                         std::to_string(size[2]) + " voxels (" + std::to_string(data) + " bytes) but the file holds " +
                         std::to_string(stream_bytes - std::uint64_t(vox_offset)) + " bytes of data",
                     path, "the file is truncated or its header is wrong; copy it again");
  // Reading costs the file's voxels and the decoded floats (4 bytes each) side by side.
  const std::uint64_t needed = voxels * std::uint64_t(4 + bytes);
  if (max_memory_bytes > 0 && needed > std::uint64_t(max_memory_bytes))
    throw InputError(ExitCode::too_large,
                     "reading it needs " + std::to_string(needed >> 20) + " MiB, more than the budget of " +
                         std::to_string(max_memory_bytes >> 20) + " MiB",
                     path, "raise --max-memory-mb ([ingest] max_memory_mb) or crop the volume");
  return facts;
}

}  // namespace organsmith
