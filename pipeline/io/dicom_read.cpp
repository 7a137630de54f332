// Over 400 lines: the structure checks and the series assembly read the same header fields and
// belong together.
// DICOM series discovery, validation and decoding with GDCM.
//
// Two passes: headers of every file first (cheap: reading stops at the pixel data), so that the
// series can be chosen and its geometry checked before anything is decoded; then the chosen
// series' pixels, decoded in parallel (JPEG 2000 decoding is CPU-bound).

#include "core/errors.h"
#include "core/memory.h"
#include "pipeline/io/dicom.h"
#include "pipeline/io/dicom_structure.h"

#include <gdcmAttribute.h>
#include <gdcmImage.h>
#include <gdcmImageHelper.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmTrace.h>
#include <gdcmTransferSyntax.h>
#include <gdcmUIDs.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>
#include <fcntl.h>
#include <unistd.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <map>
#include <mutex>
#include <numeric>
#include <optional>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

const gdcm::Tag kPixelData(0x7fe0, 0x0010);

/// Header facts of one file, as far as ingest needs them.
struct FileHeader {
  fs::path path;
  std::string series_uid, modality, description, sop_class;
  std::string transfer_syntax;
  int rows = 0, columns = 0, frames = 1;
  std::optional<Eigen::Vector3d> position_lps_mm;  // (0020,0032)
  std::optional<std::array<double, 6>> orientation;  // (0020,0037)
  std::optional<Eigen::Vector2d> pixel_spacing_mm;   // (0028,0030): row spacing, column spacing
  double slice_thickness_mm = 0.0;
  double gantry_tilt_deg = 0.0;
  bool has_pixel_data = false;
  // For the direct path (uncompressed little-endian, no bit packing); GDCM decodes the rest.
  bool raw_little_endian = false;
  int bits_allocated = 0, bits_stored = 0, high_bit = 0, pixel_representation = 0, samples_per_pixel = 1;
  std::string unreadable;  // a value that is there but is no number (the first one found)
  std::string photometric;
  double rescale_slope = 1.0, rescale_intercept = 0.0;
  std::uint64_t pixel_offset = 0, pixel_bytes = 0;  // of the pixel data value, when its length is defined
};

/// Where the pixel data value sits in a file, found by walking its elements.
struct PixelLocation {
  std::uint64_t offset = 0, bytes = 0;  // bytes = 0: undefined length (encapsulated)
};

std::string trimmed(std::string s) {
  while (!s.empty() && (s.back() == ' ' || s.back() == '\0')) s.pop_back();
  std::size_t b = 0;
  while (b < s.size() && s[b] == ' ') ++b;
  return s.substr(b);
}

std::string string_value(const gdcm::DataSet& ds, const gdcm::Tag& tag) {
  if (!ds.FindDataElement(tag)) return {};
  const gdcm::DataElement& de = ds.GetDataElement(tag);
  const gdcm::ByteValue* bv = de.GetByteValue();
  if (!bv || de.IsEmpty()) return {};
  return trimmed(std::string(bv->GetPointer(), bv->GetLength()));
}

std::vector<double> numbers(const std::string& s) {
  std::vector<double> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, '\\')) {
    try {
      out.push_back(std::stod(item));
    } catch (...) {
      return {};
    }
  }
  return out;
}

template <std::uint16_t G, std::uint16_t E>
int us_value(const gdcm::DataSet& ds) {
  gdcm::Attribute<G, E> at{};
  if (!ds.FindDataElement(at.GetTag()) || ds.GetDataElement(at.GetTag()).IsEmpty()) return 0;
  at.SetFromDataSet(ds);
  return int(at.GetValue());
}


/// Checks the byte structure of a Part-10 file up to and including the pixel data
/// (pipeline/io/dicom_structure.h): GDCM aborts on some truncated files, so truncation must be
/// caught before GDCM sees the file.
bool structurally_complete(const fs::path& path, std::string& why, PixelLocation& pixels) {
  const DicomStructure st = check_dicom_structure(path);
  if (!st.complete) {
    why = st.why;
    return false;
  }
  if (st.has_pixel_data && !st.encapsulated) pixels = {st.pixel_offset, st.pixel_bytes};
  return true;
}

/// Reads the header of `path`; nullopt when it is not DICOM or cannot be parsed.
std::optional<FileHeader> read_header(const fs::path& path, const PixelLocation& pixels) {
  gdcm::Reader reader;
  reader.SetFileName(path.string().c_str());
  if (!reader.ReadUpToTag(kPixelData)) return std::nullopt;
  const gdcm::File& file = reader.GetFile();
  const gdcm::DataSet& ds = file.GetDataSet();
  FileHeader h;
  h.path = path;
  h.sop_class = string_value(ds, gdcm::Tag(0x0008, 0x0016));
  h.series_uid = string_value(ds, gdcm::Tag(0x0020, 0x000e));
  h.modality = string_value(ds, gdcm::Tag(0x0008, 0x0060));
  h.description = string_value(ds, gdcm::Tag(0x0008, 0x103e));
  {
    gdcm::UIDs uid;
    const char* ts = gdcm::TransferSyntax::GetTSString(file.GetHeader().GetDataSetTransferSyntax());
    h.transfer_syntax = ts && uid.SetFromUID(ts) ? uid.GetName() : (ts ? ts : "unknown");
    const std::string ts_uid = ts ? ts : "";
    h.raw_little_endian = ts_uid == "1.2.840.10008.1.2" || ts_uid == "1.2.840.10008.1.2.1";
  }
  h.bits_allocated = us_value<0x0028, 0x0100>(ds);
  h.bits_stored = us_value<0x0028, 0x0101>(ds);
  h.high_bit = us_value<0x0028, 0x0102>(ds);
  h.pixel_representation = us_value<0x0028, 0x0103>(ds);
  if (ds.FindDataElement(gdcm::Tag(0x0028, 0x0002))) h.samples_per_pixel = us_value<0x0028, 0x0002>(ds);
  h.photometric = string_value(ds, gdcm::Tag(0x0028, 0x0004));
  // A value that is present must be numbers, as many as the attribute has.
  auto values = [&](std::uint16_t g, std::uint16_t e, std::size_t count, const char* name) {
    const std::string text = string_value(ds, gdcm::Tag(g, e));
    std::vector<double> v = numbers(text);
    if (!text.empty() && v.size() != count && h.unreadable.empty())
      h.unreadable = std::string(name) + " is '" + text.substr(0, 40) + "', not " + std::to_string(count) + " number(s)";
    return v.size() == count ? v : std::vector<double>{};
  };
  if (const auto v = values(0x0028, 0x1053, 1, "Rescale Slope"); !v.empty()) h.rescale_slope = v[0];
  if (const auto v = values(0x0028, 0x1052, 1, "Rescale Intercept"); !v.empty()) h.rescale_intercept = v[0];
  h.pixel_offset = pixels.offset;
  h.pixel_bytes = pixels.bytes;
  h.rows = us_value<0x0028, 0x0010>(ds);
  h.columns = us_value<0x0028, 0x0011>(ds);
  if (const auto f = numbers(string_value(ds, gdcm::Tag(0x0028, 0x0008))); f.size() == 1 && f[0] >= 1)
    h.frames = int(f[0]);
  if (const auto p = values(0x0020, 0x0032, 3, "Image Position (Patient)"); !p.empty())
    h.position_lps_mm = Eigen::Vector3d(p[0], p[1], p[2]);
  if (const auto o = values(0x0020, 0x0037, 6, "Image Orientation (Patient)"); !o.empty())
    h.orientation = std::array<double, 6>{o[0], o[1], o[2], o[3], o[4], o[5]};
  if (const auto s = values(0x0028, 0x0030, 2, "Pixel Spacing"); !s.empty())
    h.pixel_spacing_mm = Eigen::Vector2d(s[0], s[1]);
  if (const auto t = numbers(string_value(ds, gdcm::Tag(0x0018, 0x0050))); t.size() == 1)
    h.slice_thickness_mm = t[0];
  if (const auto g = numbers(string_value(ds, gdcm::Tag(0x0018, 0x1120))); g.size() == 1)
    h.gantry_tilt_deg = g[0];
  // ReadUpToTag stops before the pixel data element, so its presence is judged from the image
  // attributes; a truncated pixel payload is caught when decoding.
  h.has_pixel_data = h.rows > 0 && h.columns > 0;
  return h;
}

/// What makes a slice's pixel description unusable (empty when nothing does): checked before
/// GDCM decodes it, as GDCM aborts on some of these and reads others as garbage.
std::string pixel_module_problem(const FileHeader& h) {
  if (!h.unreadable.empty()) return h.unreadable;
  if (h.samples_per_pixel != 1)
    return "has Samples per Pixel " + std::to_string(h.samples_per_pixel) + " (organsmith reads greyscale CT: 1)";
  if (h.photometric != "MONOCHROME2" && h.photometric != "MONOCHROME1")
    return "has Photometric Interpretation '" + h.photometric + "' (greyscale CT is MONOCHROME2)";
  if (h.bits_allocated != 8 && h.bits_allocated != 16 && h.bits_allocated != 32)
    return "has Bits Allocated " + std::to_string(h.bits_allocated) + " (8, 16 or 32 expected)";
  if (h.bits_stored < 1 || h.bits_stored > h.bits_allocated || h.high_bit >= h.bits_allocated ||
      h.high_bit + 1 < h.bits_stored)
    return "has Bits Stored " + std::to_string(h.bits_stored) + " and High Bit " + std::to_string(h.high_bit) +
           " that do not fit its Bits Allocated " + std::to_string(h.bits_allocated);
  if (h.pixel_representation != 0 && h.pixel_representation != 1)
    return "has Pixel Representation " + std::to_string(h.pixel_representation) + " (0 or 1 expected)";
  if (h.pixel_bytes > 0) {  // native pixel data: its length is the image's
    const std::uint64_t need = std::uint64_t(h.rows) * std::uint64_t(h.columns) * std::uint64_t(h.frames) *
                               std::uint64_t(h.bits_allocated / 8);
    if (h.pixel_bytes != need && h.pixel_bytes != need + 1)
      return "holds " + std::to_string(h.pixel_bytes) + " bytes of pixel data where Rows " + std::to_string(h.rows) +
             " × Columns " + std::to_string(h.columns) + " × Bits Allocated " + std::to_string(h.bits_allocated) +
             (h.frames > 1 ? " × " + std::to_string(h.frames) + " frames" : std::string()) + " need " +
             std::to_string(need);
  }
  if (!std::isfinite(h.rescale_slope) || !std::isfinite(h.rescale_intercept) || h.rescale_slope == 0 ||
      std::abs(h.rescale_slope) > 1e4 || std::abs(h.rescale_intercept) > 1e6) {
    std::ostringstream m;
    m << "has Rescale Slope " << h.rescale_slope << " and Intercept " << h.rescale_intercept
      << " (a non-zero slope up to 10⁴ and an intercept up to 10⁶ HU expected)";
    return m.str();
  }
  return {};
}

std::vector<fs::path> list_files(const fs::path& input) {
  std::vector<fs::path> files;
  if (fs::is_regular_file(input)) return {input};
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(input, fs::directory_options::skip_permission_denied, ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) break;
    if (it->is_regular_file(ec)) files.push_back(it->path());
  }
  // A stable order makes warnings and tie-breaks reproducible; geometry never depends on it.
  std::sort(files.begin(), files.end());
  return files;
}

std::string fmt_mm(double v) {
  std::ostringstream s;
  s.precision(2);
  s << std::fixed << v << " mm";
  return s.str();
}

SeriesSummary summarize(const std::vector<FileHeader>& files) {
  SeriesSummary s;
  const FileHeader& h = files.front();
  s.series_uid = h.series_uid;
  s.modality = h.modality;
  s.description = h.description;
  s.rows = h.rows;
  s.columns = h.columns;
  s.transfer_syntax = h.transfer_syntax;
  for (const auto& f : files) s.files += f.frames;
  return s;
}

/// Decodes one file into float HU values (rescale applied), columns × rows × frames.
/// Value range of a decoded slice.
struct Range {
  float lo = INFINITY, hi = -INFINITY;
  void merge(const Range& o) { lo = std::min(lo, o.lo), hi = std::max(hi, o.hi); }
};

template <typename T>
Range convert(const T* px, std::size_t n, double slope, double intercept, float* out) {
  Range r;
  const float s = float(slope), b = float(intercept);
  // Split min/max from the store so the compiler vectorises both loops.
  for (std::size_t a = 0; a < n; ++a) out[a] = float(px[a]) * s + b;
  float lo = out[0], hi = out[0];
  for (std::size_t a = 0; a < n; ++a) lo = std::min(lo, out[a]), hi = std::max(hi, out[a]);
  r.lo = lo, r.hi = hi;
  return r;
}

/// The direct path: 16-bit uncompressed little-endian greyscale, read straight from the file
/// (most CT). Returns false when the file does not qualify (GDCM then decodes it).
bool decode_direct(const FileHeader& h, float* out, std::size_t expected, Range& range) {
  if (!h.raw_little_endian || h.bits_allocated != 16 || h.bits_stored != 16 || h.samples_per_pixel != 1 ||
      h.photometric != "MONOCHROME2" || h.frames != 1 || h.pixel_bytes < expected * 2)
    return false;
  thread_local std::vector<std::uint16_t> buf;
  buf.resize(expected);
  std::ifstream in(h.path, std::ios::binary);
  in.seekg(std::streamoff(h.pixel_offset));
  in.read(reinterpret_cast<char*>(buf.data()), std::streamsize(expected * 2));
  if (std::size_t(in.gcount()) != expected * 2) return false;
  range = h.pixel_representation == 1
              ? convert(reinterpret_cast<const std::int16_t*>(buf.data()), expected, h.rescale_slope, h.rescale_intercept, out)
              : convert(buf.data(), expected, h.rescale_slope, h.rescale_intercept, out);
  return true;
}

bool decode(const fs::path& path, float* out, std::size_t expected, std::string& why, Range& range) {
  gdcm::ImageReader reader;
  reader.SetFileName(path.string().c_str());
  if (!reader.Read()) {
    why = "cannot be decoded (truncated or corrupt)";
    return false;
  }
  const gdcm::Image& image = reader.GetImage();
  const gdcm::PixelFormat& pf = image.GetPixelFormat();
  if (pf.GetSamplesPerPixel() != 1) {
    why = "is not a greyscale image";
    return false;
  }
  const std::size_t n = std::size_t(image.GetDimension(0)) * image.GetDimension(1) *
                        (image.GetNumberOfDimensions() > 2 ? image.GetDimension(2) : 1);
  std::vector<char> raw(image.GetBufferLength());
  if (raw.size() < n * pf.GetPixelSize() || !image.GetBuffer(raw.data())) {
    why = "has incomplete pixel data (truncated)";
    return false;
  }
  if (n != expected) {
    why = "holds " + std::to_string(n) + " pixels where the series' slices hold " + std::to_string(expected);
    return false;
  }
  if (image.GetPhotometricInterpretation() == gdcm::PhotometricInterpretation::MONOCHROME1) {
    why = "is MONOCHROME1 (inverted greyscale), which CT does not use";
    return false;
  }
  // Bits stored below bits allocated are masked and sign-extended by GDCM.
  const double slope = image.GetSlope();
  const double intercept = image.GetIntercept();
  auto conv = [&](auto* px) { range = convert(px, n, slope, intercept, out); };
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::INT16: conv(reinterpret_cast<const std::int16_t*>(raw.data())); break;
    case gdcm::PixelFormat::UINT16: conv(reinterpret_cast<const std::uint16_t*>(raw.data())); break;
    case gdcm::PixelFormat::INT8: conv(reinterpret_cast<const std::int8_t*>(raw.data())); break;
    case gdcm::PixelFormat::UINT8: conv(reinterpret_cast<const std::uint8_t*>(raw.data())); break;
    case gdcm::PixelFormat::INT32: conv(reinterpret_cast<const std::int32_t*>(raw.data())); break;
    case gdcm::PixelFormat::UINT32: conv(reinterpret_cast<const std::uint32_t*>(raw.data())); break;
    default:
      why = std::string("has an unsupported pixel type ") + pf.GetScalarTypeAsString();
      return false;
  }
  return true;
}

void check_modality(const SeriesSummary& s, const IngestOptions& options, IngestReport& report,
                    const fs::path& input) {
  if (s.modality == "CT") return;
  const std::string msg = "series " + s.series_uid + " has modality '" + s.modality + "', not CT";
  if (!options.allow_modality)
    throw InputError(ExitCode::wrong_modality, msg, input,
                     "organsmith's organ presets assume Hounsfield units; pass --allow-modality to "
                     "read it anyway");
  report.warnings.push_back(msg + " (accepted: --allow-modality)");
}

void check_memory(std::int64_t voxels, const IngestOptions& options, const fs::path& input) {
  const std::int64_t budget =
      options.max_memory_bytes > 0 ? options.max_memory_bytes : default_memory_budget_bytes();
  const std::int64_t need = voxels * std::int64_t(sizeof(float));
  if (voxels <= 0 || need > budget) {
    std::ostringstream m;
    m << "the volume needs " << need / (1 << 20) << " MiB but the memory budget is "
      << budget / (1 << 20) << " MiB";
    throw InputError(ExitCode::too_large, m.str(), input,
                     "crop or downsample the series, or raise the budget with --max-memory-mb");
  }
}

/// Reads a single multi-frame file; GDCM resolves per-frame geometry (enhanced CT).
IngestResult read_multiframe(const FileHeader& h, const IngestOptions& options, Progress& progress) {
  IngestResult result;
  result.report.format = "DICOM multi-frame";
  result.report.series = summarize({h});
  check_modality(result.report.series, options, result.report, h.path);
  check_memory(std::int64_t(h.rows) * h.columns * h.frames, options, h.path);
  progress.report(0.0, "decoding multi-frame DICOM");
  std::string why;
  const std::size_t n = std::size_t(h.rows) * std::size_t(h.columns) * std::size_t(h.frames);
  result.volume.hu.resize(n);
  Range range;
  if (!decode(h.path, result.volume.hu.data(), n, why, range))
    throw InputError(ExitCode::corrupt_file, "the multi-frame DICOM file " + why, h.path,
                     "re-export or re-transfer the file");
  gdcm::ImageReader reader;
  reader.SetFileName(h.path.string().c_str());
  reader.Read();
  const gdcm::Image& image = reader.GetImage();
  ImageGrid& g = result.volume.grid;
  g.size_vox = {image.GetDimension(0), image.GetDimension(1),
                image.GetNumberOfDimensions() > 2 ? image.GetDimension(2) : 1};
  const double* sp = image.GetSpacing();
  const double* org = image.GetOrigin();
  const double* dc = image.GetDirectionCosines();
  g.spacing_mm = {sp[0], sp[1], sp[2] > 0 ? sp[2] : 1.0};
  g.origin_lps_mm = {org[0], org[1], org[2]};
  const Eigen::Vector3d row(dc[0], dc[1], dc[2]), col(dc[3], dc[4], dc[5]);
  g.direction_lps.col(0) = row.normalized();
  g.direction_lps.col(1) = col.normalized();
  g.direction_lps.col(2) = row.cross(col).normalized();
  g.validate();
  result.report.hu_min = range.lo;
  result.report.hu_max = range.hi;
  progress.report(1.0, "decoding multi-frame DICOM");
  return result;
}

/// What makes a slice's patient geometry unusable (empty when nothing does): spacing in
/// (0, 1000] mm, a position within 10⁵ mm, orientation two orthogonal unit vectors (to 10⁻³).
std::string geometry_problem(const FileHeader& h) {
  std::ostringstream m;
  if (h.pixel_spacing_mm && !((h.pixel_spacing_mm->array() > 0) && (h.pixel_spacing_mm->array() <= 1000)).all())
    m << "Pixel Spacing " << (*h.pixel_spacing_mm)[0] << " \\ " << (*h.pixel_spacing_mm)[1] << " mm is not in (0, 1000] mm";
  else if (h.position_lps_mm && !(h.position_lps_mm->array().abs() <= 1e5).all())
    m << "Image Position (Patient) (" << h.position_lps_mm->transpose() << ") mm is not finite or beyond 100 m";
  else if (h.orientation) {
    const auto& o = *h.orientation;
    const Eigen::Vector3d r(o[0], o[1], o[2]), c(o[3], o[4], o[5]);
    if (!(std::abs(r.norm() - 1) < 1e-3 && std::abs(c.norm() - 1) < 1e-3 && std::abs(r.dot(c)) < 1e-3))
      m << "Image Orientation (Patient) (" << r.transpose() << ", " << c.transpose()
        << ") is not two orthogonal unit vectors";
  }
  return m.str();
}

/// Sorted slices of one series and its geometry, validated.
struct Stack {
  std::vector<const FileHeader*> slices;  // sorted along the normal
  ImageGrid grid;
};

Stack build_stack(std::vector<const FileHeader*> slices, const IngestOptions& options,
                  const std::vector<fs::path>& corrupt, const fs::path& input, const std::string& foreign_note) {
  const FileHeader& first = *slices.front();
  if (!first.orientation || !first.pixel_spacing_mm)
    throw InputError(ExitCode::unsupported_input,
                     "slice lacks Image Orientation (Patient) or Pixel Spacing", first.path,
                     "organsmith needs patient geometry to place the organs in millimetres");
  if (const std::string why = geometry_problem(first); !why.empty())
    throw InputError(ExitCode::bad_geometry, "the slice's " + why, first.path,
                     "re-export the series; its patient geometry is damaged");
  const auto& o = *first.orientation;
  const Eigen::Vector3d row = Eigen::Vector3d(o[0], o[1], o[2]).normalized();
  const Eigen::Vector3d col = Eigen::Vector3d(o[3], o[4], o[5]).normalized();
  const Eigen::Vector3d normal = row.cross(col).normalized();

  for (const FileHeader* h : slices) {
    if (!h->position_lps_mm || !h->orientation)
      throw InputError(ExitCode::unsupported_input, "slice lacks Image Position (Patient)", h->path,
                       "organsmith sorts slices by position; this file cannot be placed");
    if (const std::string why = geometry_problem(*h); !why.empty())
      throw InputError(ExitCode::bad_geometry, "the slice's " + why, h->path,
                       "re-export the series; its patient geometry is damaged");
    const auto& q = *h->orientation;
    const double dev = std::max((Eigen::Vector3d(q[0], q[1], q[2]).normalized() - row).norm(),
                                (Eigen::Vector3d(q[3], q[4], q[5]).normalized() - col).norm());
    if (dev > 1e-3)
      throw InputError(ExitCode::unsupported_input, "slices of one series have different orientations",
                       h->path, "pass --series to pick a series with a single orientation");
    if (h->rows != first.rows || h->columns != first.columns)
      throw InputError(ExitCode::unsupported_input, "slices of one series have different sizes", h->path);
  }
  auto along = [&](const FileHeader* h) { return normal.dot(*h->position_lps_mm); };
  std::stable_sort(slices.begin(), slices.end(),
                   [&](const FileHeader* a, const FileHeader* b) { return along(a) < along(b); });

  Stack stack;
  stack.grid.size_vox = {first.columns, first.rows, std::int64_t(slices.size())};
  stack.grid.direction_lps.col(0) = row;
  stack.grid.direction_lps.col(1) = col;
  stack.grid.direction_lps.col(2) = normal;
  stack.grid.origin_lps_mm = *slices.front()->position_lps_mm;
  // Pixel Spacing is (spacing between rows, spacing between columns) = (dj, di).
  stack.grid.spacing_mm.x() = (*first.pixel_spacing_mm)[1];
  stack.grid.spacing_mm.y() = (*first.pixel_spacing_mm)[0];

  if (slices.size() == 1) {
    stack.grid.spacing_mm.z() = first.slice_thickness_mm > 0 ? first.slice_thickness_mm : 1.0;
    stack.slices = std::move(slices);
    stack.grid.validate();
    return stack;
  }

  std::vector<double> steps;
  for (std::size_t a = 1; a < slices.size(); ++a) steps.push_back(along(slices[a]) - along(slices[a - 1]));
  for (std::size_t a = 0; a < steps.size(); ++a)
    if (std::abs(steps[a]) < 1e-4)
      throw InputError(ExitCode::unsupported_input,
                       "two slices share one position (" + fmt_mm(along(slices[a])) + " along the normal)",
                       slices[a + 1]->path,
                       "the directory may hold two acquisitions of one series; keep one of them");
  std::vector<double> sorted = steps;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];

  for (std::size_t a = 0; a < steps.size(); ++a) {
    if (steps[a] > options.gap_factor * median) {
      const int missing = int(std::lround(steps[a] / median)) - 1;
      std::ostringstream m;
      m << "missing slice" << (missing > 1 ? "s" : "") << ": " << std::max(missing, 1)
        << " slice(s) absent between " << fmt_mm(along(slices[a])) << " ("
        << slices[a]->path.filename().string() << ") and " << fmt_mm(along(slices[a + 1])) << " ("
        << slices[a + 1]->path.filename().string() << ") along the slice normal; expected step "
        << fmt_mm(median);
      if (!corrupt.empty())
        throw InputError(ExitCode::corrupt_file,
                         "a corrupt file leaves the series incomplete (" + m.str() + ")",
                         corrupt.front(), "re-export or re-transfer the corrupt file");
      throw InputError(ExitCode::missing_slice, m.str() + foreign_note, input,
                       "re-export the complete series from the PACS or scanner");
    }
  }
  double worst = 0.0;
  std::size_t worst_at = 0;
  for (std::size_t a = 0; a < steps.size(); ++a) {
    const double dev = std::abs(steps[a] - median) / median;
    if (dev > worst) worst = dev, worst_at = a;
  }
  if (worst > options.spacing_tolerance) {
    std::ostringstream m;
    m << "slice spacing is not uniform: step " << fmt_mm(steps[worst_at]) << " between "
      << slices[worst_at]->path.filename().string() << " and " << slices[worst_at + 1]->path.filename().string()
      << " differs from the median " << fmt_mm(median)
      << " by " << std::lround(worst * 100) << " % (tolerance "
      << options.spacing_tolerance * 100 << " %)";
    throw InputError(ExitCode::nonuniform_spacing, m.str(), input,
                     "resample the series to uniform spacing before segmenting it");
  }

  const Eigen::Vector3d span = *slices.back()->position_lps_mm - *slices.front()->position_lps_mm;
  const double tilt_deg = std::atan2((span - normal * normal.dot(span)).norm(), normal.dot(span)) * 180.0 / M_PI;
  if (tilt_deg > options.tilt_tolerance_deg) {
    std::ostringstream m;
    m.precision(2);
    m << std::fixed << "gantry tilt: slices are stacked at " << tilt_deg
      << "° to their normal (Gantry/Detector Tilt tag: " << first.gantry_tilt_deg << "°)";
    throw InputError(ExitCode::gantry_tilt, m.str(), input,
                     "resample the series onto an orthogonal grid (e.g. with a tilt-correction tool) "
                     "before using it");
  }
  stack.grid.spacing_mm.z() = span.norm() / double(slices.size() - 1);
  stack.slices = std::move(slices);
  stack.grid.validate();
  return stack;
}

}  // namespace

bool has_dicom_magic(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  char magic[4] = {};
  in.seekg(128);
  in.read(magic, 4);
  return in.gcount() == 4 && std::string(magic, 4) == "DICM";
}

IngestResult read_dicom(const fs::path& input, const IngestOptions& options, Progress& progress) {
  const std::vector<fs::path> files = list_files(input);
  if (files.empty())
    throw InputError(ExitCode::no_dicom, "the directory is empty", input,
                     "point organsmith at the folder that holds the series' .dcm files");

  // Pass 1: headers.
  // Ask the kernel to start reading every file now: the header and decode passes then find
  // their pages in memory instead of waiting on the disk two requests at a time.
  for (const auto& f : files) {
    const int fd = open(f.c_str(), O_RDONLY);
    if (fd < 0) continue;
    posix_fadvise(fd, 0, 0, POSIX_FADV_WILLNEED);
    close(fd);
  }
  gdcm::Trace::SetWarning(false);  // GDCM's own chatter; problems are reported by organsmith
  gdcm::Trace::SetDebug(false);
  std::vector<std::optional<FileHeader>> headers(files.size());
  std::vector<std::string> broken(files.size());
  std::atomic<std::size_t> done{0};
  tbb::parallel_for(std::size_t(0), files.size(), [&](std::size_t a) {
    // Only Part-10 files (with the "DICM" preamble) are considered; GDCM is given only files
    // whose element lengths are consistent with their size.
    PixelLocation px;
    if (has_dicom_magic(files[a]) && structurally_complete(files[a], broken[a], px)) headers[a] = read_header(files[a], px);
    if (headers[a] && headers[a]->has_pixel_data)
      if (std::string why = pixel_module_problem(*headers[a]); !why.empty()) broken[a] = std::move(why), headers[a].reset();
    const std::size_t d = ++done;
    if (d % 64 == 0) progress.report(0.1 * double(d) / double(files.size()), "scanning DICOM headers");
  });

  std::vector<fs::path> corrupt;  // DICOM by their preamble but unreadable
  std::map<std::string, std::vector<FileHeader>> series;
  std::size_t non_dicom = 0, non_image = 0;
  std::string foreign_note;  // names of files that are not DICOM, for a missing slice's message
  std::vector<std::string> report_early;
  for (std::size_t a = 0; a < files.size(); ++a) {
    if (!headers[a]) {
      if (has_dicom_magic(files[a])) {
        corrupt.push_back(files[a]);
        report_early.push_back("skipped " + files[a].filename().string() + ": it " +
                               (broken[a].empty() ? std::string("cannot be parsed") : broken[a]));
      } else {
        if (++non_dicom <= 3) foreign_note += (non_dicom == 1 ? "; not DICOM here: " : ", ") + files[a].filename().string();
      }
      continue;
    }
    if (!headers[a]->has_pixel_data) {
      ++non_image;  // DICOMDIR, structured reports, presentation states …
      continue;
    }
    series[headers[a]->series_uid].push_back(std::move(*headers[a]));
  }
  if (series.empty()) {
    if (!corrupt.empty())
      throw InputError(ExitCode::corrupt_file,
                       "no readable DICOM image; " + std::to_string(corrupt.size()) +
                           " file(s) look like DICOM but cannot be parsed",
                       corrupt.front(), "re-export or re-transfer the series");
    throw InputError(ExitCode::no_dicom,
                     "no DICOM image found among " + std::to_string(files.size()) + " file(s)", input,
                     "point organsmith at the folder that holds the series' .dcm files, or give a "
                     "NIfTI/NRRD/MHA file");
  }

  // Choose the series.
  const std::vector<FileHeader>* chosen = nullptr;
  if (!options.series_uid.empty()) {
    const auto it = series.find(options.series_uid);
    if (it == series.end()) {
      std::string seen;
      for (const auto& [uid, f] : series) seen += "\n  " + uid + " (" + f.front().modality + ", " + std::to_string(f.size()) + " files)";
      throw InputError(ExitCode::series_not_found, "no series with UID " + options.series_uid, input,
                       "series present:" + seen);
    }
    chosen = &it->second;
  } else {
    auto score = [](const std::vector<FileHeader>& f) {
      int frames = 0;
      for (const auto& h : f) frames += h.frames;
      return std::pair<int, int>(f.front().modality == "CT" ? 1 : 0, frames);
    };
    for (const auto& [uid, f] : series)
      if (!chosen || score(f) > score(*chosen)) chosen = &f;
  }

  IngestResult result;
  IngestReport& report = result.report;
  report.series = summarize(*chosen);
  report.warnings = report_early;
  for (const auto& [uid, f] : series)
    if (&f != chosen) report.other_series.push_back(summarize(f));
  if (non_dicom > 0) report.warnings.push_back("ignored " + std::to_string(non_dicom) + " non-DICOM file(s)");
  if (non_image > 0) report.warnings.push_back("ignored " + std::to_string(non_image) + " DICOM file(s) without an image");
  check_modality(report.series, options, report, input);

  if (chosen->size() == 1 && chosen->front().frames > 1) {
    IngestResult mf = read_multiframe(chosen->front(), options, progress);
    mf.report.other_series = std::move(report.other_series);
    mf.report.warnings.insert(mf.report.warnings.begin(), report.warnings.begin(), report.warnings.end());
    return mf;
  }
  check_memory(std::int64_t(chosen->front().rows) * chosen->front().columns * std::int64_t(chosen->size()),
               options, input);

  // Pass 2: geometry from the headers, then decode every slice straight into its place.
  std::vector<const FileHeader*> slices;
  for (const auto& h : *chosen) slices.push_back(&h);
  Stack stack = build_stack(slices, options, corrupt, input, foreign_note);
  Volume& vol = result.volume;
  auto decode_stack = [&](const Stack& st) {
    vol.grid = st.grid;
    vol.hu.resize(std::size_t(vol.grid.voxel_count()));
    const std::size_t per_slice = std::size_t(vol.grid.slice_voxel_count());
    std::vector<std::string> failure(st.slices.size());
    std::vector<Range> ranges(st.slices.size());
    done = 0;
    tbb::parallel_for(std::size_t(0), st.slices.size(), [&](std::size_t k) {
      progress.check_cancelled();
      float* dst = vol.hu.data() + k * per_slice;
      if (!decode_direct(*st.slices[k], dst, per_slice, ranges[k]))
        decode(st.slices[k]->path, dst, per_slice, failure[k], ranges[k]);
      const std::size_t d = ++done;
      progress.report(0.1 + 0.9 * double(d) / double(st.slices.size()), "decoding slices");
    });
    std::vector<const FileHeader*> good;
    Range all;
    for (std::size_t k = 0; k < st.slices.size(); ++k) {
      if (failure[k].empty()) {
        good.push_back(st.slices[k]);
        all.merge(ranges[k]);
        continue;
      }
      corrupt.push_back(st.slices[k]->path);
      report.warnings.push_back("skipped " + st.slices[k]->path.filename().string() + ": it " + failure[k]);
    }
    report.hu_min = all.lo;
    report.hu_max = all.hi;
    return good;
  };
  std::vector<const FileHeader*> good = decode_stack(stack);
  if (good.empty())
    throw InputError(ExitCode::corrupt_file, "no slice of the series can be decoded", corrupt.front(),
                     "re-export or re-transfer the series");
  if (good.size() != stack.slices.size()) {
    // Without the corrupt slices the stack must still be complete (build_stack names the
    // corrupt file when it is not); the layout changed, so decode again.
    stack = build_stack(good, options, corrupt, input, foreign_note);
    decode_stack(stack);
  }
  if (!corrupt.empty())
    report.warnings.push_back(std::to_string(corrupt.size()) +
                              " corrupt file(s) skipped; the remaining slices form a complete series");
  report.format = "DICOM";
  report.series.files = int(stack.slices.size());
  progress.report(1.0, "decoding slices");
  return result;
}

}  // namespace organsmith
