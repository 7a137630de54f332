// Ingest: real DICOM series against their reference NIfTI geometry, slice ordering, and each
// kind of bad input with its own error code.

#include "core/errors.h"
#include "pipeline/io/dicom.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "tests/support/test_support.h"

#include <gdcmImageWriter.h>
#include <gdcmReader.h>
#include <gdcmWriter.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>

using namespace organsmith;
using organsmith::testing::ScratchDir;
namespace fs = std::filesystem;

namespace {

/// Maps every corner of `ours` into `ref`'s index space; true when each lands within tol_vox of
/// a corner of `ref` and all of ref's corners are hit (same voxel lattice, any axis order/flip).
bool same_lattice(const ImageGrid& ours, const ImageGrid& ref, double tol_vox, std::string& why) {
  std::vector<std::array<long, 3>> hit;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d ijk((c & 1) ? double(ours.size_vox[0] - 1) : 0.0,
                              (c & 2) ? double(ours.size_vox[1] - 1) : 0.0,
                              (c & 4) ? double(ours.size_vox[2] - 1) : 0.0);
    const Eigen::Vector3d r = ref.lps_mm_to_index(ours.index_to_lps_mm(ijk));
    std::array<long, 3> idx{};
    for (int a = 0; a < 3; ++a) {
      idx[a] = std::lround(r[a]);
      if (std::abs(r[a] - double(idx[a])) > tol_vox) {
        why = "corner " + std::to_string(c) + " falls between reference voxels (axis " + std::to_string(a) +
              " at " + std::to_string(r[a]) + ")";
        return false;
      }
      if (idx[a] != 0 && idx[a] != ref.size_vox[a] - 1) {
        why = "corner " + std::to_string(c) + " maps to reference index " + std::to_string(idx[a]) +
              " on axis " + std::to_string(a) + ", not a corner";
        return false;
      }
    }
    hit.push_back(idx);
  }
  std::sort(hit.begin(), hit.end());
  if (std::unique(hit.begin(), hit.end()) != hit.end()) {
    why = "two corners map to one reference corner";
    return false;
  }
  return true;
}

/// HU values of `vol` at the voxels carrying `label` in `ref` (matched through physical space).
std::vector<float> hu_under_label(const Volume& vol, const LabelMap& ref, std::uint8_t label) {
  std::vector<float> out;
  for (std::int64_t k = 0; k < ref.grid.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < ref.grid.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < ref.grid.size_vox[0]; ++i) {
        if (ref.at(i, j, k) != label) continue;
        const Eigen::Vector3d v = vol.grid.lps_mm_to_index(ref.grid.index_to_lps_mm(Eigen::Vector3d(i, j, k)));
        const long a = std::lround(v.x()), b = std::lround(v.y()), c = std::lround(v.z());
        if (vol.grid.contains(a, b, c)) out.push_back(vol.at(a, b, c));
      }
  return out;
}

float median(std::vector<float> v) {
  std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
  return v[v.size() / 2];
}

/// A small volume whose value encodes its index, so any mis-ordering of slices or axes shows.
Volume coded_volume(int n = 32, int slices = 12, double slice_mm = 5.0) {
  Volume v;
  v.grid.size_vox = {n, n, slices};
  v.grid.spacing_mm = {1.25, 1.25, slice_mm};
  v.grid.origin_lps_mm = {-20.0, -20.0, -100.0};
  v.hu.resize(std::size_t(v.grid.voxel_count()));
  for (std::int64_t k = 0; k < slices; ++k)
    for (std::int64_t j = 0; j < n; ++j)
      for (std::int64_t i = 0; i < n; ++i) v.hu[v.grid.offset(i, j, k)] = float(i + 40 * j + 1500 * k) - 1000.0f;
  return v;
}

fs::path write_coded_series(const fs::path& dir, const Volume& v) {
  NullProgress np;
  DicomSeriesIds ids;
  ids.uid_seed = "test-series";
  write_dicom_series(v, dir, ids, np);
  return dir;
}

std::vector<fs::path> sorted_files(const fs::path& dir) {
  std::vector<fs::path> f;
  for (const auto& e : fs::directory_iterator(dir)) f.push_back(e.path());
  std::sort(f.begin(), f.end());
  return f;
}

/// Rewrites one string attribute of a DICOM file in place.
void rewrite(const fs::path& file, std::uint16_t g, std::uint16_t e, const gdcm::VR& vr, std::string value) {
  gdcm::Reader r;
  r.SetFileName(file.string().c_str());
  ASSERT_TRUE(r.Read()) << file;
  if (value.size() % 2) value.push_back(' ');
  gdcm::DataElement de(gdcm::Tag(g, e));
  de.SetVR(vr);
  de.SetByteValue(value.data(), std::uint32_t(value.size()));
  r.GetFile().GetDataSet().Replace(de);
  gdcm::Writer w;
  w.SetFile(r.GetFile());
  w.SetFileName(file.string().c_str());
  ASSERT_TRUE(w.Write()) << file;
}

std::string ipp(double x, double y, double z) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.4f\\%.4f\\%.4f", x, y, z);
  return buf;
}

ExitCode ingest_code(const fs::path& dir, IngestOptions o = {}) {
  NullProgress np;
  try {
    ingest(dir, o, np);
  } catch (const Error& e) {
    return e.code();
  }
  return ExitCode::ok;
}

}  // namespace

// ---- real series ---------------------------------------------------------------------------

TEST(IngestReal, ChestSeriesMatchesReferenceGeometryAndTracheaIsAir) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const fs::path base = organsmith::testing::real_data_dir() / "chest-dicom-8mm";
  NullProgress np;
  const IngestResult r = ingest(base / "dicom", {}, np);
  EXPECT_EQ(r.report.format, "DICOM");
  EXPECT_EQ(r.volume.grid.size_vox, (std::array<std::int64_t, 3>{512, 512, 30}));
  const LabelMap ref = read_label_map(base / "trachea-reference.nii.gz");
  std::string why;
  EXPECT_TRUE(same_lattice(r.volume.grid, ref.grid, 0.01, why)) << why;
  // The reference lumen was traced below −500 HU: our voxels at the same physical places must be air.
  const auto hu = hu_under_label(r.volume, ref, 1);
  ASSERT_GT(hu.size(), 1000u);
  EXPECT_LT(median(hu), -800.0f);
  EXPECT_LT(r.report.hu_min, -900.0f);
  EXPECT_GT(r.report.hu_max, 300.0f);  // bone
}

TEST(IngestReal, Jpeg2000AbdomenMatchesReferenceGeometryAndLiverIsSoftTissue) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const fs::path base = organsmith::testing::real_data_dir() / "abdomen-dicom-2mm";
  NullProgress np;
  const IngestResult r = ingest(base / "dicom", {}, np);
  EXPECT_NE(r.report.series.transfer_syntax.find("2000"), std::string::npos) << r.report.series.transfer_syntax;
  EXPECT_EQ(r.volume.grid.size_vox, (std::array<std::int64_t, 3>{512, 512, 20}));
  EXPECT_NEAR(r.volume.grid.spacing_mm.z(), 2.0, 1e-3);
  const LabelMap ref = read_label_map(base / "labels-reference.nii.gz");
  std::string why;
  EXPECT_TRUE(same_lattice(r.volume.grid, ref.grid, 0.01, why)) << why;
  const auto liver = hu_under_label(r.volume, ref, 5);
  ASSERT_GT(liver.size(), 1000u);
  EXPECT_GT(median(liver), 30.0f);  // rescale intercept applied: liver is ~40–70 HU
  EXPECT_LT(median(liver), 100.0f);
}

// ---- ordering and formats -----------------------------------------------------------------

TEST(Ingest, SortsByPositionNotByFileNameOrInstanceNumber) {
  ScratchDir tmp("order");
  const Volume v = coded_volume();
  const auto files = sorted_files(write_coded_series(tmp / "dicom", v));
  // Reverse the file names and scramble instance numbers.
  for (std::size_t a = 0; a < files.size(); ++a) {
    rewrite(files[a], 0x0020, 0x0013, gdcm::VR::IS, std::to_string((a * 7) % files.size() + 1));
    fs::rename(files[a], tmp / "dicom" / ("z" + std::to_string(files.size() - a) + ".dcm"));
  }
  NullProgress np;
  const IngestResult r = ingest(tmp / "dicom", {}, np);
  EXPECT_TRUE(r.volume.grid.same_geometry(v.grid, 1e-3));
  EXPECT_EQ(r.volume.hu, v.hu);
}

TEST(Ingest, NiftiRoundTripKeepsGeometryWithObliqueDirections) {
  ScratchDir tmp("nifti");
  Volume v = coded_volume(16, 6);
  const double c = std::cos(0.3), s = std::sin(0.3);
  v.grid.direction_lps << c, -s, 0, s, c, 0, 0, 0, 1;
  for (const char* name : {"v.nii.gz", "v.nrrd", "v.mha"}) {
    write_volume_file(v, tmp / name);
    NullProgress np;
    const IngestResult r = ingest(tmp / name, {}, np);
    EXPECT_TRUE(r.volume.grid.same_geometry(v.grid, 1e-4)) << name;
    EXPECT_EQ(r.volume.hu, v.hu) << name;
  }
}

TEST(Ingest, DigestDependsOnPixelsAndGeometryOnly) {
  const Volume a = coded_volume(8, 3);
  Volume b = a;
  EXPECT_EQ(volume_digest(a), volume_digest(b));
  b.hu[5] += 1;
  EXPECT_NE(volume_digest(a), volume_digest(b));
  b = a;
  b.grid.origin_lps_mm.x() += 0.5;
  EXPECT_NE(volume_digest(a), volume_digest(b));
}

// ---- bad inputs: each has its own code -----------------------------------------------------

TEST(IngestErrors, EmptyAndNonDicomDirectories) {
  ScratchDir tmp("empty");
  fs::create_directories(tmp / "empty");
  EXPECT_EQ(ingest_code(tmp / "empty"), ExitCode::no_dicom);
  fs::create_directories(tmp / "text");
  std::ofstream(tmp / "text" / "notes.txt") << "not an image";
  EXPECT_EQ(ingest_code(tmp / "text"), ExitCode::no_dicom);
  EXPECT_EQ(ingest_code(tmp / "does-not-exist"), ExitCode::input_not_found);
}

TEST(IngestErrors, TruncatedSliceFailsButStrayCorruptFileIsSkipped) {
  ScratchDir tmp("corrupt");
  const auto files = sorted_files(write_coded_series(tmp / "dicom", coded_volume()));
  // A stray corrupt file beside a complete series: skipped with a warning.
  {
    std::ifstream in(files[0], std::ios::binary);
    std::string head(400, '\0');
    in.read(head.data(), 400);
    std::ofstream(tmp / "dicom" / "stray.dcm", std::ios::binary) << head;
  }
  NullProgress np;
  const IngestResult ok = ingest(tmp / "dicom", {}, np);
  EXPECT_EQ(ok.volume.grid.size_vox[2], 12);
  EXPECT_FALSE(ok.report.warnings.empty());
  // Truncating a slice of the series leaves a hole: that is an error naming the corrupt file.
  fs::resize_file(files[5], fs::file_size(files[5]) / 2);
  EXPECT_EQ(ingest_code(tmp / "dicom"), ExitCode::corrupt_file);
}

TEST(IngestErrors, MissingSliceIsNamed) {
  ScratchDir tmp("gap");
  const auto files = sorted_files(write_coded_series(tmp / "dicom", coded_volume()));
  fs::remove(files[6]);
  NullProgress np;
  try {
    ingest(tmp / "dicom", {}, np);
    FAIL() << "a series with a gap was accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.code(), ExitCode::missing_slice);
    EXPECT_NE(std::string(e.what()).find(files[5].filename().string()), std::string::npos) << e.what();
  }
}

TEST(IngestErrors, NonUniformSpacing) {
  ScratchDir tmp("spacing");
  const Volume v = coded_volume();
  const auto files = sorted_files(write_coded_series(tmp / "dicom", v));
  // Move the upper half of the stack 1 mm up: one step of 6 mm among steps of 5 mm (20 %).
  for (std::size_t k = 6; k < files.size(); ++k)
    rewrite(files[k], 0x0020, 0x0032, gdcm::VR::DS, ipp(-20.0, -20.0, -100.0 + 5.0 * double(k) + 1.0));
  EXPECT_EQ(ingest_code(tmp / "dicom"), ExitCode::nonuniform_spacing);
  IngestOptions lenient;
  lenient.spacing_tolerance = 0.25;
  EXPECT_EQ(ingest_code(tmp / "dicom", lenient), ExitCode::ok);
}

TEST(IngestErrors, GantryTilt) {
  ScratchDir tmp("tilt");
  const auto files = sorted_files(write_coded_series(tmp / "dicom", coded_volume()));
  // Each slice shifted posteriorly by tan(15°) × 5 mm: stacked obliquely to the slice normal.
  for (std::size_t k = 0; k < files.size(); ++k)
    rewrite(files[k], 0x0020, 0x0032, gdcm::VR::DS,
            ipp(-20.0, -20.0 + std::tan(15.0 * M_PI / 180.0) * 5.0 * double(k), -100.0 + 5.0 * double(k)));
  EXPECT_EQ(ingest_code(tmp / "dicom"), ExitCode::gantry_tilt);
}

TEST(IngestErrors, NonCtModalityNeedsPermission) {
  ScratchDir tmp("modality");
  const auto files = sorted_files(write_coded_series(tmp / "dicom", coded_volume()));
  for (const auto& f : files) rewrite(f, 0x0008, 0x0060, gdcm::VR::CS, "MR");
  EXPECT_EQ(ingest_code(tmp / "dicom"), ExitCode::wrong_modality);
  IngestOptions allow;
  allow.allow_modality = true;
  NullProgress np;
  const IngestResult r = ingest(tmp / "dicom", allow, np);
  EXPECT_EQ(r.report.series.modality, "MR");
  EXPECT_FALSE(r.report.warnings.empty());
}

TEST(IngestErrors, TooLargeForTheMemoryBudgetAndUnknownSeries) {
  ScratchDir tmp("large");
  write_coded_series(tmp / "dicom", coded_volume());
  IngestOptions small;
  small.max_memory_bytes = 1000;  // the coded volume needs 49 kB
  EXPECT_EQ(ingest_code(tmp / "dicom", small), ExitCode::too_large);
  IngestOptions other;
  other.series_uid = "1.2.3.4";
  EXPECT_EQ(ingest_code(tmp / "dicom", other), ExitCode::series_not_found);
}

// ---- multi-frame ------------------------------------------------------------------------------

TEST(Ingest, EnhancedMultiFrameCtFile) {
  ScratchDir tmp("multiframe");
  const Volume v = coded_volume(20, 7, 3.0);
  std::vector<std::int16_t> px(v.hu.size());
  for (std::size_t a = 0; a < px.size(); ++a) px[a] = std::int16_t(std::lround(v.hu[a]) + 1024);  // stored = HU + 1024

  gdcm::ImageWriter w;
  gdcm::Image& im = w.GetImage();
  im.SetNumberOfDimensions(3);
  for (unsigned a = 0; a < 3; ++a) im.SetDimension(a, unsigned(v.grid.size_vox[a]));
  im.SetPixelFormat(gdcm::PixelFormat::INT16);
  im.SetPhotometricInterpretation(gdcm::PhotometricInterpretation::MONOCHROME2);
  im.SetTransferSyntax(gdcm::TransferSyntax::ExplicitVRLittleEndian);
  for (unsigned a = 0; a < 3; ++a) {
    im.SetOrigin(a, v.grid.origin_lps_mm[a]);
    im.SetSpacing(a, v.grid.spacing_mm[a]);
  }
  const double dircos[6] = {1, 0, 0, 0, 1, 0};
  im.SetDirectionCosines(dircos);
  im.SetIntercept(-1024.0);
  im.SetSlope(1.0);
  gdcm::DataElement pixel_data(gdcm::Tag(0x7fe0, 0x0010));
  pixel_data.SetByteValue(reinterpret_cast<const char*>(px.data()), std::uint32_t(px.size() * 2));
  im.SetDataElement(pixel_data);
  gdcm::DataSet& ds = w.GetFile().GetDataSet();
  auto put = [&](std::uint16_t g, std::uint16_t e, const gdcm::VR& vr, std::string s) {
    if (s.size() % 2) s.push_back(vr == gdcm::VR::UI ? '\0' : ' ');
    gdcm::DataElement de(gdcm::Tag(g, e));
    de.SetVR(vr);
    de.SetByteValue(s.data(), std::uint32_t(s.size()));
    ds.Replace(de);
  };
  put(0x0008, 0x0016, gdcm::VR::UI, "1.2.840.10008.5.1.4.1.1.2.1");  // Enhanced CT Image Storage
  put(0x0008, 0x0018, gdcm::VR::UI, "2.25.1234567");
  put(0x0008, 0x0060, gdcm::VR::CS, "CT");
  put(0x0020, 0x000e, gdcm::VR::UI, "2.25.7654321");
  w.SetFileName((tmp / "enhanced.dcm").string().c_str());
  ASSERT_TRUE(w.Write());

  NullProgress np;
  const IngestResult r = ingest(tmp / "enhanced.dcm", {}, np);
  EXPECT_EQ(r.report.format, "DICOM multi-frame");
  EXPECT_TRUE(r.volume.grid.same_geometry(v.grid, 1e-3))
      << r.volume.grid.origin_lps_mm.transpose() << " / " << r.volume.grid.spacing_mm.transpose();
  EXPECT_EQ(r.volume.hu, v.hu);
}
