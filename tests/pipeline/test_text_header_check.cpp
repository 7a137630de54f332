// NRRD and MetaImage headers checked before ITK reads them (pipeline/io/text_header_check.h): well
// formed files (written by hand and by ITK) read; each corrupt field is refused with its code.

#include "core/errors.h"
#include "pipeline/io/image_io.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace organsmith {
namespace {

namespace fs = std::filesystem;

std::string floats(std::size_t n) {
  std::string b(n * 4, '\0');
  for (std::size_t i = 0; i < n; ++i) {
    const float v = float(i) - 5.0f;
    std::memcpy(b.data() + 4 * i, &v, 4);
  }
  return b;
}

std::string gzipped(const std::string& raw) {
  z_stream z{};
  EXPECT_EQ(deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(raw.size() + 1024, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(raw.data()));
  z.avail_in = unsigned(raw.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = unsigned(out.size());
  EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
  out.resize(out.size() - z.avail_out);
  deflateEnd(&z);
  return out;
}

/// The exit code reading `path` ends with (0 = read).
int code_of(const fs::path& path, std::int64_t budget = 0) {
  try {
    read_volume_file(path, budget);
    return 0;
  } catch (const Error& e) {
    return int(e.code());
  }
}

void write(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

const std::string kData = floats(4 * 3 * 2);

std::string nrrd(const std::string& fields, const std::string& data = kData) {
  return "NRRD0004\n# written by a test\n" + fields + "\n" + data;
}

const char* kGood = "type: float\ndimension: 3\nspace: left-posterior-superior\nsizes: 4 3 2\n"
                    "space directions: (0.8,0,0) (0,0.8,0) (0,0,2.5)\nkinds: domain domain domain\n"
                    "endian: little\nencoding: raw\nspace origin: (1,2,3)\n";

std::string with(std::string text, const std::string& from, const std::string& to) {
  text.replace(text.find(from), from.size(), to);
  return text;
}

TEST(TextHeaders, NrrdFieldsAreCheckedBeforeItkReadsTheFile) {
  testing::ScratchDir tmp("nrrd-check");
  write(tmp / "good.nrrd", nrrd(kGood));
  ASSERT_EQ(code_of(tmp / "good.nrrd"), 0);
  const Volume v = read_volume_file(tmp / "good.nrrd");
  EXPECT_EQ(v.grid.size_vox[0], 4);
  EXPECT_NEAR(v.grid.spacing_mm.z(), 2.5, 1e-9);
  EXPECT_FLOAT_EQ(v.hu[7], 2.0f);
  write(tmp / "gz.nrrd", nrrd(with(kGood, "encoding: raw", "encoding: gzip"), gzipped(kData)));
  EXPECT_EQ(code_of(tmp / "gz.nrrd"), 0);
  const std::string gz = gzipped(kData);
  const struct {
    const char* name;
    std::string text;
    ExitCode code;
  } bad[] = {
      {"short.nrrd", nrrd(kGood, kData.substr(0, kData.size() - 1)), ExitCode::corrupt_file},
      {"cut-gzip.nrrd", nrrd(with(kGood, "encoding: raw", "encoding: gzip"), gz.substr(0, gz.size() / 2)),
       ExitCode::corrupt_file},
      {"negative.nrrd", nrrd(with(kGood, "sizes: 4 3 2", "sizes: 4 -3 2")), ExitCode::unsupported_input},
      {"nan.nrrd", nrrd(with(kGood, "(0,0,2.5)", "(0,0,nan)")), ExitCode::bad_geometry},
      {"singular.nrrd", nrrd(with(kGood, "(0,0,2.5)", "(0.8,0,0)")), ExitCode::bad_geometry},
      {"origin.nrrd", nrrd(with(kGood, "(1,2,3)", "(1,inf,3)")), ExitCode::bad_geometry},
      {"block.nrrd", nrrd(with(kGood, "type: float", "type: block")), ExitCode::unsupported_input},
      {"vector.nrrd",
       nrrd(with(with(with(kGood, "dimension: 3", "dimension: 4"), "sizes: 4 3 2", "sizes: 3 4 3 2"),
                 "kinds: domain domain domain", "kinds: vector domain domain domain")),
       ExitCode::unsupported_input},
      {"bzip.nrrd", nrrd(with(kGood, "encoding: raw", "encoding: bzip2")), ExitCode::unsupported_input},
      {"nodim.nrrd", nrrd(with(kGood, "dimension: 3\n", "")), ExitCode::unsupported_input},
      {"detached.nhdr", "NRRD0004\n" + with(kGood, "encoding: raw\n", "encoding: raw\ndata file: missing.raw\n") + "\n",
       ExitCode::input_not_found},
      {"notnrrd.nrrd", "hello\n\n", ExitCode::unsupported_input},
  };
  for (const auto& b : bad) {
    write(tmp / b.name, b.text);
    EXPECT_EQ(code_of(tmp / b.name), int(b.code)) << b.name;
  }
  // 32767 × 32767 × 1 floats announced over 96 bytes: refused from the header, before allocating.
  write(tmp / "huge.nrrd", nrrd(with(kGood, "sizes: 4 3 2", "sizes: 32767 32767 1")));
  EXPECT_EQ(code_of(tmp / "huge.nrrd", std::int64_t(256) << 20), int(ExitCode::too_large));
  EXPECT_EQ(code_of(tmp / "huge.nrrd", std::int64_t(64) << 30), int(ExitCode::corrupt_file));
}

const char* kMeta = "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
                    "CompressedData = False\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = 1 2 3\n"
                    "ElementSpacing = 0.8 0.8 2.5\nDimSize = 4 3 2\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n";

TEST(TextHeaders, MetaImageFieldsAreCheckedBeforeItkReadsTheFile) {
  testing::ScratchDir tmp("mha-check");
  write(tmp / "good.mha", std::string(kMeta) + kData);
  ASSERT_EQ(code_of(tmp / "good.mha"), 0);
  EXPECT_FLOAT_EQ(read_volume_file(tmp / "good.mha").hu[7], 2.0f);
  std::string z(compressBound(uLong(kData.size())), '\0');
  uLongf zn = uLongf(z.size());
  ASSERT_EQ(compress(reinterpret_cast<Bytef*>(z.data()), &zn, reinterpret_cast<const Bytef*>(kData.data()), uLong(kData.size())), Z_OK);
  z.resize(zn);
  const std::string zhead = with(with(kMeta, "CompressedData = False", "CompressedData = True"), "ElementType",
                                 "CompressedDataSize = " + std::to_string(zn) + "\nElementType");
  write(tmp / "z.mha", zhead + z);
  EXPECT_EQ(code_of(tmp / "z.mha"), 0);
  const struct {
    const char* name;
    std::string text;
    ExitCode code;
  } bad[] = {
      {"short.mha", std::string(kMeta) + kData.substr(0, 10), ExitCode::corrupt_file},
      {"cut.mha", zhead + z.substr(0, z.size() / 2), ExitCode::corrupt_file},
      {"negative.mha", with(kMeta, "DimSize = 4 3 2", "DimSize = 4 0 2") + kData, ExitCode::unsupported_input},
      {"zero.mha", with(kMeta, "0.8 0.8 2.5", "0.8 0 2.5") + kData, ExitCode::bad_geometry},
      {"nan.mha", with(kMeta, "Offset = 1 2 3", "Offset = 1 nan 3") + kData, ExitCode::bad_geometry},
      {"singular.mha", with(kMeta, "1 0 0 0 1 0 0 0 1", "1 0 0 1 0 0 0 0 1") + kData, ExitCode::bad_geometry},
      {"rgb.mha", with(kMeta, "ElementType", "ElementNumberOfChannels = 3\nElementType") + kData,
       ExitCode::unsupported_input},
      {"array.mha", with(kMeta, "MET_FLOAT", "MET_FLOAT_ARRAY") + kData, ExitCode::unsupported_input},
      {"4d.mha", with(with(kMeta, "NDims = 3", "NDims = 4"), "DimSize = 4 3 2", "DimSize = 4 3 2 5") + kData,
       ExitCode::unsupported_input},
      {"missing.mhd", with(kMeta, "LOCAL", "missing.raw"), ExitCode::input_not_found},
  };
  for (const auto& b : bad) {
    write(tmp / b.name, b.text);
    EXPECT_EQ(code_of(tmp / b.name), int(b.code)) << b.name;
  }
  write(tmp / "huge.mha", with(kMeta, "DimSize = 4 3 2", "DimSize = 32767 32767 1") + kData);
  EXPECT_EQ(code_of(tmp / "huge.mha", std::int64_t(256) << 20), int(ExitCode::too_large));
}

TEST(TextHeaders, ItkWrittenNrrdAndMetaImageFilesPass) {
  testing::ScratchDir tmp("itk-written");
  Volume v;
  v.grid.size_vox = {7, 5, 3};
  v.grid.spacing_mm = {0.7, 0.7, 3.0};
  v.hu.resize(std::size_t(v.grid.voxel_count()));
  for (std::size_t i = 0; i < v.hu.size(); ++i) v.hu[i] = float(i);
  for (const char* name : {"v.nrrd", "v.mha", "v.nhdr", "v.mhd"}) {
    write_volume_file(v, tmp / name);
    EXPECT_EQ(code_of(tmp / name), 0) << name;
  }
}

}  // namespace
}  // namespace organsmith
