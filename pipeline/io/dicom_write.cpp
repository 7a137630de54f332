// Writes a Volume as a CT Image Storage series with GDCM (used for the phantom).

#include "core/errors.h"
#include "core/sha256.h"
#include "pipeline/io/dicom.h"

#include <gdcmImage.h>
#include <gdcmImageWriter.h>
#include <gdcmTrace.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

/// A UID under the "2.25" root (ISO/IEC 9834-8: a 128-bit integer in decimal), derived from
/// `key` so that the same phantom always carries the same UIDs.
std::string uid_from(const std::string& key) {
  const std::string hex = sha256_hex(key).substr(0, 32);
  std::vector<int> bytes;
  for (std::size_t a = 0; a < 32; a += 2) bytes.push_back(std::stoi(hex.substr(a, 2), nullptr, 16));
  // Repeated division of the 128-bit big-endian number by 10.
  std::string digits;
  bool nonzero = true;
  while (nonzero) {
    int rem = 0;
    nonzero = false;
    for (int& b : bytes) {
      const int cur = rem * 256 + b;
      b = cur / 10;
      rem = cur % 10;
      nonzero |= b != 0;
    }
    digits.push_back(char('0' + rem));
  }
  return "2.25." + std::string(digits.rbegin(), digits.rend());
}

std::string ds_string(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s.precision(6);
  s << std::fixed << v.x() << '\\' << v.y() << '\\' << v.z();
  return s.str();
}

void put_string(gdcm::DataSet& ds, std::uint16_t g, std::uint16_t e, const gdcm::VR& vr, std::string value) {
  if (value.size() % 2) value.push_back(vr == gdcm::VR::UI ? '\0' : ' ');
  gdcm::DataElement de(gdcm::Tag(g, e));
  de.SetVR(vr);
  de.SetByteValue(value.data(), std::uint32_t(value.size()));
  ds.Replace(de);
}

}  // namespace

void write_dicom_series(const Volume& volume, const fs::path& dir, const DicomSeriesIds& ids,
                        Progress& progress) {
  const ImageGrid& g = volume.grid;
  const std::int64_t nk = g.size_vox[2];
  const std::size_t per_slice = std::size_t(g.slice_voxel_count());
  const std::string study_uid = uid_from(ids.uid_seed + "/study");
  const std::string series_uid = uid_from(ids.uid_seed + "/series");
  const std::string frame_uid = uid_from(ids.uid_seed + "/frame");
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw OutputError("cannot create the DICOM output directory: " + ec.message(), dir);

  gdcm::Trace::SetWarning(false);  // GDCM warns about attributes it fills in itself
  std::atomic<std::int64_t> done{0};
  std::atomic<bool> failed{false};
  tbb::parallel_for(std::int64_t(0), nk, [&](std::int64_t k) {
    if (failed || progress.cancelled()) return;
    std::vector<std::int16_t> px(per_slice);
    const float* src = volume.slice(k);
    for (std::size_t a = 0; a < per_slice; ++a)
      px[a] = std::int16_t(std::lround(std::clamp(src[a], -32768.0f, 32767.0f)));

    gdcm::ImageWriter writer;
    gdcm::Image& image = writer.GetImage();
    image.SetNumberOfDimensions(2);
    image.SetDimension(0, unsigned(g.size_vox[0]));
    image.SetDimension(1, unsigned(g.size_vox[1]));
    image.SetPixelFormat(gdcm::PixelFormat::INT16);
    image.SetPhotometricInterpretation(gdcm::PhotometricInterpretation::MONOCHROME2);
    image.SetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
    const Eigen::Vector3d origin = g.index_to_lps_mm(Eigen::Vector3d(0, 0, double(k)));
    image.SetOrigin(0, origin.x());
    image.SetOrigin(1, origin.y());
    image.SetOrigin(2, origin.z());
    image.SetSpacing(0, g.spacing_mm.x());
    image.SetSpacing(1, g.spacing_mm.y());
    image.SetSpacing(2, g.spacing_mm.z());
    const double dircos[6] = {g.direction_lps(0, 0), g.direction_lps(1, 0), g.direction_lps(2, 0),
                              g.direction_lps(0, 1), g.direction_lps(1, 1), g.direction_lps(2, 1)};
    image.SetDirectionCosines(dircos);
    image.SetIntercept(0.0);
    image.SetSlope(1.0);
    gdcm::DataElement pixel_data(gdcm::Tag(0x7fe0, 0x0010));
    pixel_data.SetByteValue(reinterpret_cast<const char*>(px.data()),
                            std::uint32_t(px.size() * sizeof(std::int16_t)));
    image.SetDataElement(pixel_data);

    gdcm::DataSet& ds = writer.GetFile().GetDataSet();
    char instance[16];
    std::snprintf(instance, sizeof instance, "%lld", static_cast<long long>(k + 1));
    put_string(ds, 0x0008, 0x0016, gdcm::VR::UI, "1.2.840.10008.5.1.4.1.1.2");  // CT Image Storage
    put_string(ds, 0x0008, 0x0018, gdcm::VR::UI, uid_from(ids.uid_seed + "/instance/" + instance));
    put_string(ds, 0x0008, 0x0008, gdcm::VR::CS, "ORIGINAL\\PRIMARY\\AXIAL");
    put_string(ds, 0x0008, 0x0020, gdcm::VR::DA, "20260101");
    put_string(ds, 0x0008, 0x0021, gdcm::VR::DA, "20260101");
    put_string(ds, 0x0008, 0x0030, gdcm::VR::TM, "120000");
    put_string(ds, 0x0008, 0x0060, gdcm::VR::CS, "CT");
    put_string(ds, 0x0008, 0x0070, gdcm::VR::LO, "organsmith");
    put_string(ds, 0x0008, 0x103e, gdcm::VR::LO, ids.series_description);
    put_string(ds, 0x0010, 0x0010, gdcm::VR::PN, ids.patient_name);
    put_string(ds, 0x0010, 0x0020, gdcm::VR::LO, ids.patient_id);
    put_string(ds, 0x0010, 0x0030, gdcm::VR::DA, "");
    put_string(ds, 0x0010, 0x0040, gdcm::VR::CS, "O");
    put_string(ds, 0x0018, 0x0050, gdcm::VR::DS, std::to_string(g.spacing_mm.z()).substr(0, 16));
    put_string(ds, 0x0018, 0x0060, gdcm::VR::DS, "120");
    put_string(ds, 0x0020, 0x000d, gdcm::VR::UI, study_uid);
    put_string(ds, 0x0020, 0x000e, gdcm::VR::UI, series_uid);
    put_string(ds, 0x0020, 0x0010, gdcm::VR::SH, "1");
    put_string(ds, 0x0020, 0x0011, gdcm::VR::IS, "1");
    put_string(ds, 0x0020, 0x0013, gdcm::VR::IS, instance);
    put_string(ds, 0x0020, 0x0052, gdcm::VR::UI, frame_uid);
    put_string(ds, 0x0020, 0x0032, gdcm::VR::DS, ds_string(origin));
    put_string(ds, 0x0028, 0x0004, gdcm::VR::CS, "MONOCHROME2");
    put_string(ds, 0x0028, 0x1050, gdcm::VR::DS, "40");
    put_string(ds, 0x0028, 0x1051, gdcm::VR::DS, "400");

    char name[32];
    std::snprintf(name, sizeof name, "IM%04lld.dcm", static_cast<long long>(k + 1));
    // GDCM asserts (and aborts) when its file stream fails half-way, as on a full disk: the slice
    // is encoded into memory, and organsmith writes and checks the file itself.
    std::ostringstream encoded(std::ios::out | std::ios::binary);
    writer.SetStream(encoded);
    if (!writer.Write()) {
      failed = true;
      return;
    }
    const std::string bytes = encoded.str();
    std::ofstream file(dir / name, std::ios::binary | std::ios::trunc);
    file.write(bytes.data(), std::streamsize(bytes.size()));
    file.flush();
    if (!file) {
      failed = true;
      return;
    }
    const std::int64_t d = ++done;
    if (d % 16 == 0 || d == nk) progress.report(double(d) / double(nk), "writing DICOM slices");
  });
  progress.check_cancelled();
  if (failed) throw OutputError("cannot write a DICOM slice (disk full or not writable?)", dir);
}

}  // namespace organsmith
