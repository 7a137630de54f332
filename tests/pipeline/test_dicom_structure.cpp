// The DICOM byte-structure check (pipeline/io/dicom_structure.h): synthetic files in each transfer
// syntax with sequences and items of undefined length, encapsulated pixel data and every prefix
// of them; real slices cut anywhere; real series re-encoded by DCMTK's dcmconv (explicit VR big
// endian, deflated, implicit VR) read to the same voxels.

#include "core/progress.h"
#include "pipeline/io/dicom_structure.h"
#include "pipeline/io/ingest.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

namespace organsmith {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<unsigned char>;

/// Writes data elements in one transfer syntax's encoding.
struct Enc {
  bool explicit_vr = true, big = false;
  Bytes b;
  void u16(std::uint16_t v) {
    if (big) b.insert(b.end(), {std::uint8_t(v >> 8), std::uint8_t(v)});
    else b.insert(b.end(), {std::uint8_t(v), std::uint8_t(v >> 8)});
  }
  void u32(std::uint32_t v) {
    if (big) b.insert(b.end(), {std::uint8_t(v >> 24), std::uint8_t(v >> 16), std::uint8_t(v >> 8), std::uint8_t(v)});
    else b.insert(b.end(), {std::uint8_t(v), std::uint8_t(v >> 8), std::uint8_t(v >> 16), std::uint8_t(v >> 24)});
  }
  void tag(std::uint16_t g, std::uint16_t e) { u16(g), u16(e); }
  /// An element header; `len` 0xffffffff for undefined length.
  void head(std::uint16_t g, std::uint16_t e, const char* vr, std::uint32_t len) {
    tag(g, e);
    if (!explicit_vr) return u32(len);
    b.push_back(std::uint8_t(vr[0]));
    b.push_back(std::uint8_t(vr[1]));
    const std::string v = vr;
    if (v == "OB" || v == "OW" || v == "SQ" || v == "UN" || v == "UT") {
      u16(0);
      u32(len);
    } else {
      u16(std::uint16_t(len));
    }
  }
  void element(std::uint16_t g, std::uint16_t e, const char* vr, const std::string& value) {
    head(g, e, vr, std::uint32_t(value.size()));
    b.insert(b.end(), value.begin(), value.end());
  }
  void item_start(std::uint32_t len = 0xffffffffu) { tag(0xfffe, 0xe000), u32(len); }
  void item_end() { tag(0xfffe, 0xe00d), u32(0); }
  void seq_end() { tag(0xfffe, 0xe0dd), u32(0); }
};

Bytes meta(const std::string& ts) {
  Bytes b(128, 0);
  b.insert(b.end(), {'D', 'I', 'C', 'M'});
  Enc m;
  std::string t = ts;
  if (t.size() % 2) t.push_back('\0');
  m.element(0x0002, 0x0010, "UI", t);
  b.insert(b.end(), m.b.begin(), m.b.end());
  return b;
}

/// A data set with a sequence of undefined length holding an item of undefined length (with a
/// nested sequence) and one of defined length, then `pixels` (native) or two fragments.
Bytes data_set(bool explicit_vr, bool big, bool encapsulated) {
  Enc e{explicit_vr, big, {}};
  e.element(0x0008, 0x0060, "CS", "CT");
  e.head(0x0008, 0x1140, "SQ", 0xffffffffu);
  e.item_start();
  e.element(0x0008, 0x1150, "UI", "1.2.3.4");
  e.head(0x0040, 0xa730, "SQ", 0xffffffffu);
  e.item_start();
  e.element(0x0040, 0xa010, "CS", "CONTAINS");
  e.item_end();
  e.seq_end();
  e.item_end();
  Enc inner{explicit_vr, big, {}};
  inner.element(0x0008, 0x1155, "UI", "1.2.3.5\0");
  e.item_start(std::uint32_t(inner.b.size()));
  e.b.insert(e.b.end(), inner.b.begin(), inner.b.end());
  e.seq_end();
  e.element(0x0028, 0x0010, "US", big ? std::string("\0\4", 2) : std::string("\4\0", 2));
  if (!encapsulated) {
    e.head(0x7fe0, 0x0010, "OW", 32);
    for (int i = 0; i < 32; ++i) e.b.push_back(std::uint8_t(i));
  } else {
    e.head(0x7fe0, 0x0010, "OB", 0xffffffffu);
    e.item_start(0);  // empty basic offset table
    e.item_start(10);
    for (int i = 0; i < 10; ++i) e.b.push_back(std::uint8_t(i));
    e.item_start(6);
    for (int i = 0; i < 6; ++i) e.b.push_back(std::uint8_t(i));
    e.seq_end();
  }
  return e.b;
}

Bytes deflate_raw(const Bytes& in) {
  z_stream z{};
  EXPECT_EQ(deflateInit2(&z, 9, Z_DEFLATED, -15, 8, Z_DEFAULT_STRATEGY), Z_OK);
  Bytes out(in.size() + 1024);
  z.next_in = const_cast<unsigned char*>(in.data());
  z.avail_in = unsigned(in.size());
  z.next_out = out.data();
  z.avail_out = unsigned(out.size());
  EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
  out.resize(out.size() - z.avail_out);
  deflateEnd(&z);
  return out;
}

struct Syntax {
  const char* uid;
  bool explicit_vr, big, encapsulated, deflated;
};

TEST(DicomStructure, EverySyntaxWalksWholeFilesAndRefusesEveryCutOne) {
  const Syntax syntaxes[] = {{"1.2.840.10008.1.2", false, false, false, false},
                             {"1.2.840.10008.1.2.1", true, false, false, false},
                             {"1.2.840.10008.1.2.2", true, true, false, false},
                             {"1.2.840.10008.1.2.4.90", true, false, true, false},
                             {"1.2.840.10008.1.2.1.99", true, false, false, true}};
  for (const Syntax& s : syntaxes) {
    Bytes file = meta(s.uid);
    const std::size_t data_start = file.size();
    const Bytes ds = data_set(s.explicit_vr, s.big, s.encapsulated);
    const Bytes body = s.deflated ? deflate_raw(ds) : ds;
    file.insert(file.end(), body.begin(), body.end());
    const DicomStructure whole = check_dicom_structure(file.data(), file.size());
    ASSERT_TRUE(whole.complete) << s.uid << ": " << whole.why;
    EXPECT_TRUE(whole.has_pixel_data) << s.uid;
    EXPECT_EQ(whole.encapsulated, s.encapsulated) << s.uid;
    EXPECT_EQ(whole.transfer_syntax, s.uid);
    if (s.encapsulated) EXPECT_EQ(whole.fragment_bytes, 16u);
    else EXPECT_EQ(whole.pixel_bytes, 32u) << s.uid;
    if (!s.encapsulated && !s.deflated) EXPECT_EQ(whole.pixel_offset, file.size() - 32) << s.uid;
    // Every prefix that cuts into the data set is refused (the pixel data comes last).
    int refused = 0;
    for (std::size_t n = data_start + 1; n < file.size(); ++n) {
      const DicomStructure cut = check_dicom_structure(file.data(), n);
      ASSERT_FALSE(cut.complete && cut.has_pixel_data) << s.uid << " cut to " << n << " bytes was taken as whole";
      refused += !cut.complete;
    }
    std::printf("%s: %zu bytes, %d of %zu cuts refused outright, the rest hold no pixel data\n", s.uid, file.size(),
                refused, file.size() - data_start - 1);
  }
}

TEST(DicomStructure, HostileNestingAndStrayItemsAreRefusedNotFollowed) {
  Bytes file = meta("1.2.840.10008.1.2.1");
  Enc e;
  for (int i = 0; i < 100000; ++i) {  // 100 000 nested sequences: no stack overflow, refused
    e.head(0x0008, 0x1140, "SQ", 0xffffffffu);
    e.item_start();
  }
  file.insert(file.end(), e.b.begin(), e.b.end());
  const DicomStructure deep = check_dicom_structure(file.data(), file.size());
  EXPECT_FALSE(deep.complete);
  EXPECT_NE(deep.why.find("nests sequences deeper"), std::string::npos) << deep.why;
  // An element inside encapsulated pixel data where a fragment should be.
  Bytes bad = meta("1.2.840.10008.1.2.4.90");
  Enc p;
  p.head(0x7fe0, 0x0010, "OB", 0xffffffffu);
  p.element(0x0008, 0x0060, "CS", "CT");
  bad.insert(bad.end(), p.b.begin(), p.b.end());
  const DicomStructure frag = check_dicom_structure(bad.data(), bad.size());
  EXPECT_FALSE(frag.complete);
  EXPECT_NE(frag.why.find("encapsulated"), std::string::npos) << frag.why;
  // A preamble without DICM, and an empty file.
  Bytes none(200, 0);
  EXPECT_EQ(check_dicom_structure(none.data(), none.size()).why, "has no DICOM preamble");
  EXPECT_FALSE(check_dicom_structure(none.data(), 0).complete);
}

TEST(DicomStructure, RealSlicesCutAnywhereAreRefused) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  // A native (chest) and a JPEG 2000 (abdomen) slice: whole, then cut 1000 bytes into the pixel
  // data and at 40 other places.
  for (const char* dir : {"chest-dicom-8mm/dicom", "abdomen-dicom-2mm/dicom"}) {
    fs::path slice;
    for (const auto& e : fs::recursive_directory_iterator(organsmith::testing::real_data_dir() / dir))
      if (e.is_regular_file() && e.path().extension() != ".gz" && e.path().filename() != "README.md") {
        slice = e.path();
        break;
      }
    ASSERT_FALSE(slice.empty()) << dir;
    std::ifstream in(slice, std::ios::binary);
    const Bytes b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const DicomStructure whole = check_dicom_structure(b.data(), b.size());
    ASSERT_TRUE(whole.complete) << slice << ": " << whole.why;
    ASSERT_TRUE(whole.has_pixel_data);
    EXPECT_EQ(check_dicom_structure(slice).complete, true);
    const std::size_t into_pixels = std::size_t(whole.pixel_offset) + 1000;
    ASSERT_LT(into_pixels, b.size());
    EXPECT_FALSE(check_dicom_structure(b.data(), into_pixels).complete) << slice << " cut into its pixel data";
    for (int i = 1; i <= 40; ++i) {
      const std::size_t n = 132 + (b.size() - 133) * std::size_t(i) / 41;
      const DicomStructure cut = check_dicom_structure(b.data(), n);
      EXPECT_FALSE(cut.complete && cut.has_pixel_data) << slice << " cut to " << n << " bytes";
    }
    std::printf("%s: %s, %zu bytes, pixel data at %llu (%s)\n", dir, whole.transfer_syntax.c_str(), b.size(),
                (unsigned long long)whole.pixel_offset, whole.encapsulated ? "encapsulated" : "native");
  }
}

TEST(DicomStructure, SeriesReencodedByDcmtkReadToTheSameVoxels) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  if (std::system("command -v dcmconv > /dev/null 2>&1") != 0) GTEST_SKIP() << "dcmconv (Debian dcmtk) is not installed";
  const fs::path src = organsmith::testing::real_data_dir() / "chest-dicom-8mm" / "dicom";
  NullProgress np;
  const Volume ref = ingest(src, IngestOptions{}, np).volume;
  organsmith::testing::ScratchDir tmp("dicom-syntaxes");
  for (const auto& [flag, name] : {std::pair{"+tb", "big-endian"}, {"+td", "deflated"}, {"+ti", "implicit"}}) {
    const fs::path dir = tmp / name;
    fs::create_directories(dir);
    int n = 0;
    for (const auto& e : fs::directory_iterator(src)) {
      const fs::path out = dir / e.path().filename();
      const std::string cmd = std::string("dcmconv ") + flag + " " + organsmith::testing::quoted(e.path()) + " " +
                              organsmith::testing::quoted(out) + " > /dev/null 2>&1";
      ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
      const DicomStructure st = check_dicom_structure(out);
      ASSERT_TRUE(st.complete) << out << ": " << st.why;
      ++n;
    }
    const IngestResult r = ingest(dir, IngestOptions{}, np);
    ASSERT_TRUE(r.volume.grid.same_geometry(ref.grid)) << name;
    ASSERT_EQ(r.volume.hu.size(), ref.hu.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < ref.hu.size(); ++i) differ += r.volume.hu[i] != ref.hu[i];
    EXPECT_EQ(differ, 0u) << name;
    std::printf("%s: %d slices, every voxel equal to the original series\n", name, n);
  }
}

}  // namespace
}  // namespace organsmith
