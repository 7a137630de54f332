// The corpus generator: volumes and their corruptions (DICOM, NIfTI, NRRD, MetaImage). Label
// maps, case files, CSVs and output paths are in corpus_gen_more.cpp.
#include "corpus_gen.h"

#include "core/progress.h"
#include "core/volume.h"
#include "pipeline/io/dicom.h"
#include "tests/support/test_support.h"

#include <gdcmDataElement.h>
#include <gdcmReader.h>
#include <gdcmWriter.h>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>

namespace organsmith::testing {

namespace fs = std::filesystem;

namespace {

void write_bytes(const fs::path& p, const std::string& bytes) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary).write(bytes.data(), std::streamsize(bytes.size()));
}

/// A 24 × 24 × 6 CT: air around a 40 HU body with a −5 HU lumen, 0.8 × 0.8 × 2.5 mm.
Volume tiny_ct() {
  Volume v;
  v.grid.size_vox = {24, 24, 6};
  v.grid.spacing_mm = {0.8, 0.8, 2.5};
  v.grid.origin_lps_mm = {-10, -10, 0};
  v.hu.resize(std::size_t(v.grid.voxel_count()));
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 24; ++j)
      for (int i = 0; i < 24; ++i) {
        const double r = std::hypot(i - 11.5, j - 11.5);
        v.hu[std::size_t(v.grid.offset(i, j, k))] = r < 4 ? -5.0f : r < 10 ? 40.0f : -1000.0f;
      }
  return v;
}

/// Replaces (or, with `remove`, deletes) one element of a DICOM file through GDCM.
void edit_dicom(const fs::path& f, std::uint16_t g, std::uint16_t e, gdcm::VR vr, std::string value, bool remove = false) {
  gdcm::Reader r;
  r.SetFileName(f.c_str());
  if (!r.Read()) throw std::runtime_error("corpus: cannot re-read " + f.string());
  gdcm::DataSet& ds = r.GetFile().GetDataSet();
  if (remove) {
    ds.Remove(gdcm::Tag(g, e));
  } else {
    if (value.size() % 2) value += (vr == gdcm::VR::UI ? '\0' : ' ');
    gdcm::DataElement de(gdcm::Tag(g, e));
    de.SetVR(vr);
    de.SetByteValue(value.data(), std::uint32_t(value.size()));
    ds.Replace(de);
  }
  gdcm::Writer w;
  w.SetFile(r.GetFile());
  w.SetFileName(f.c_str());
  if (!w.Write()) throw std::runtime_error("corpus: cannot write " + f.string());
}

std::string us(std::uint16_t v) { return std::string{char(v & 0xFF), char(v >> 8)}; }

}  // namespace

std::string nifti_bytes(int nx, int ny, int nz, short datatype, const std::vector<float>& values, float spacing_mm) {
  std::string h(352, '\0');
  auto put = [&](std::size_t off, const auto& v) { std::memcpy(&h[off], &v, sizeof v); };
  put(0, std::int32_t(348));
  const std::int16_t dim[8] = {3, std::int16_t(nx), std::int16_t(ny), std::int16_t(nz), 1, 1, 1, 1};
  std::memcpy(&h[40], dim, sizeof dim);
  const short bitpix = datatype == 4 ? 16 : datatype == 16 ? 32 : 8;
  put(70, datatype), put(72, bitpix);
  const float pixdim[8] = {1, spacing_mm, spacing_mm, spacing_mm, 0, 0, 0, 0};
  std::memcpy(&h[76], pixdim, sizeof pixdim);
  put(108, 352.0f), put(112, 1.0f), put(116, 0.0f);
  put(123, char(10));                        // xyzt_units: mm, s
  put(254, std::int16_t(1));                 // sform_code: scanner
  const float srow[12] = {spacing_mm, 0, 0, 0, 0, spacing_mm, 0, 0, 0, 0, spacing_mm, 0};
  std::memcpy(&h[280], srow, sizeof srow);
  std::memcpy(&h[344], "n+1\0", 4);
  std::string data;
  for (float v : values) {
    if (datatype == 4) {
      const std::int16_t s = std::int16_t(v);
      data.append(reinterpret_cast<const char*>(&s), 2);
    } else if (datatype == 16) {
      data.append(reinterpret_cast<const char*>(&v), 4);
    } else {
      data += char(std::uint8_t(v));
    }
  }
  return h + data;
}

std::vector<CorpusCase> dicom_corpus(const fs::path& root, std::mt19937& rng) {
  const fs::path base = root / "base";
  NullProgress quiet;
  write_dicom_series(tiny_ct(), base, DicomSeriesIds{.uid_seed = "corpus"}, quiet);
  std::vector<CorpusCase> cases;
  int n = 0;
  // A fresh copy of the series, changed by `edit`; `info` reads it.
  auto add = [&](const std::string& name, bool must_fail, const std::function<void(const fs::path&)>& edit,
                 const std::string& named = "") {
    const fs::path dir = root / ("c" + std::to_string(n++));
    fs::copy(base, dir);
    edit(dir);
    cases.push_back({"dicom", name, "info " + quoted(dir), named.empty() ? dir : dir / named, {}, dir, must_fail});
  };
  const std::string slice = "IM0003.dcm";
  auto all = [&](std::uint16_t g, std::uint16_t e, gdcm::VR vr, const std::string& v) {
    return [=](const fs::path& d) {
      for (const auto& f : fs::directory_iterator(d)) edit_dicom(f.path(), g, e, vr, v);
    };
  };
  auto one = [&](std::uint16_t g, std::uint16_t e, gdcm::VR vr, const std::string& v, bool remove = false) {
    return [=](const fs::path& d) { edit_dicom(d / slice, g, e, vr, v, remove); };
  };
  for (int v : {0, 1, 23, 25, 65535}) add("Rows " + std::to_string(v), true, all(0x28, 0x10, gdcm::VR::US, us(v)));
  for (int v : {0, 65535}) add("Columns " + std::to_string(v), true, all(0x28, 0x11, gdcm::VR::US, us(v)));
  for (int v : {0, 1, 8, 12, 32, 64}) add("BitsAllocated " + std::to_string(v), true, all(0x28, 0x100, gdcm::VR::US, us(v)));
  for (int v : {0, 17, 33}) add("BitsStored " + std::to_string(v), true, all(0x28, 0x101, gdcm::VR::US, us(v)));
  add("HighBit 20", true, all(0x28, 0x102, gdcm::VR::US, us(20)));
  add("PixelRepresentation 2", false, all(0x28, 0x103, gdcm::VR::US, us(2)));
  for (int v : {0, 3}) add("SamplesPerPixel " + std::to_string(v), true, all(0x28, 0x2, gdcm::VR::US, us(v)));
  for (const char* v : {"RGB", "PALETTE COLOR"}) add(std::string("Photometric ") + v, true, all(0x28, 0x4, gdcm::VR::CS, v));
  for (const char* v : {"nan", "inf", "-inf", "1e308", "abc"})
    add(std::string("RescaleSlope ") + v, true, all(0x28, 0x1053, gdcm::VR::DS, v));
  add("RescaleSlope 0", false, all(0x28, 0x1053, gdcm::VR::DS, "0"));
  add("RescaleSlope empty", false, all(0x28, 0x1053, gdcm::VR::DS, ""));
  for (const char* v : {"nan", "1e308", "-inf"})
    add(std::string("RescaleIntercept ") + v, true, all(0x28, 0x1052, gdcm::VR::DS, v));
  for (const char* v : {"0\\0", "-1\\-1", "nan\\nan", "1e308\\1e308", "1", "a\\b"})
    add(std::string("PixelSpacing ") + v, true, all(0x28, 0x30, gdcm::VR::DS, v));
  for (const char* v : {"nan\\0\\0", "inf\\0\\0", "1e308\\0\\0", "0\\0"})
    add(std::string("ImagePosition of one slice ") + v, true, one(0x20, 0x32, gdcm::VR::DS, v), slice);
  for (const char* v : {"2\\0\\0\\0\\2\\0", "0\\0\\0\\0\\0\\0", "nan\\0\\0\\0\\1\\0", "1\\0\\0\\1\\0\\0"})
    add(std::string("ImageOrientation ") + v, true, all(0x20, 0x37, gdcm::VR::DS, v));
  add("SliceThickness nan", false, all(0x18, 0x50, gdcm::VR::DS, "nan"));
  add("Modality MR", true, all(0x8, 0x60, gdcm::VR::CS, "MR"));
  add("NumberOfFrames 1000 on one slice", true, one(0x28, 0x8, gdcm::VR::IS, "1000"), slice);
  add("PixelData removed from one slice", true, one(0x7FE0, 0x10, gdcm::VR::OW, "", true), slice);
  add("ImagePosition removed from one slice", false, one(0x20, 0x32, gdcm::VR::DS, "", true));
  add("a slice duplicated", false, [&](const fs::path& d) { fs::copy_file(d / slice, d / "IM0099.dcm"); });
  add("a middle slice missing", true, [&](const fs::path& d) { fs::remove(d / slice); });
  add("one slice 1 mm off", true, one(0x20, 0x32, gdcm::VR::DS, "-10\\-10\\6"), slice);
  add("one slice in another series", false, one(0x20, 0xE, gdcm::VR::UI, "1.2.3.4.5.6.7"));
  const std::size_t size = fs::file_size(base / slice);
  for (int t = 0; t < 15; ++t) {
    const std::size_t at = std::uniform_int_distribution<std::size_t>(0, size - 1)(rng);
    add("a slice cut at byte " + std::to_string(at), true, [=](const fs::path& d) { fs::resize_file(d / slice, at); }, slice);
  }
  for (int t = 0; t < 25; ++t) {
    std::vector<std::pair<std::size_t, char>> flips;
    for (int k = 0; k < 4; ++k)
      flips.emplace_back(std::uniform_int_distribution<std::size_t>(128, std::min<std::size_t>(size, 1200) - 1)(rng),
                         char(std::uniform_int_distribution<int>(0, 255)(rng)));
    add("4 header bytes of a slice changed (" + std::to_string(flips[0].first) + ", …)", false, [=](const fs::path& d) {
      std::fstream f(d / slice, std::ios::in | std::ios::out | std::ios::binary);
      for (const auto& [at, b] : flips) f.seekp(std::streamoff(at)), f.put(b);
    });  // the slice may now be another series' or no DICOM: the message names the folder
  }
  for (std::size_t len : {0u, 3u, 5000u}) {
    std::string junk(len, '\0');
    for (auto& c : junk) c = char(rng());
    add("a foreign file of " + std::to_string(len) + " bytes beside the series", false,
        [=](const fs::path& d) { write_bytes(d / "IM9999.dcm", junk); });
  }
  // Whole inputs that are no series at all.
  auto whole = [&](const std::string& name, const std::function<void(const fs::path&)>& make, bool file) {
    const fs::path dir = root / ("c" + std::to_string(n++));
    fs::create_directories(dir);
    make(dir);
    const fs::path input = file ? dir / "x.dcm" : dir;
    cases.push_back({"dicom", name, "info " + quoted(input), input, {}, dir, true});
  };
  whole("an empty folder", [](const fs::path&) {}, false);
  whole("a folder of text", [](const fs::path& d) { write_bytes(d / "notes.txt", "not a scan\n"); }, false);
  whole("a file of preamble and DICM only", [](const fs::path& d) { write_bytes(d / "x.dcm", std::string(128, '\0') + "DICM"); }, true);
  whole("an empty .dcm file", [](const fs::path& d) { write_bytes(d / "x.dcm", ""); }, true);
  whole("a lone slice cut in its pixels", [&](const fs::path& d) {
    fs::copy_file(base / slice, d / "x.dcm");
    fs::resize_file(d / "x.dcm", size - 100);
  }, true);
  whole("a lone slice without pixel data", [&](const fs::path& d) {
    fs::copy_file(base / slice, d / "x.dcm");
    edit_dicom(d / "x.dcm", 0x7FE0, 0x10, gdcm::VR::OW, "", true);
  }, true);
  return cases;
}

std::vector<CorpusCase> nifti_corpus(const fs::path& root, std::mt19937& rng) {
  std::vector<float> values(16 * 16 * 8);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = float(int(i % 97) - 40);
  const std::string base = nifti_bytes(16, 16, 8, 4, values, 1.5f);
  std::vector<CorpusCase> cases;
  int n = 0;
  auto add_bytes = [&](const std::string& name, bool must_fail, const std::string& bytes, const std::string& ext = ".nii") {
    const fs::path f = root / ("c" + std::to_string(n++) + ext);
    write_bytes(f, bytes);
    cases.push_back({"nifti", name, "info " + quoted(f), f, {}, f, must_fail});
  };
  auto patch = [&](const std::string& name, bool must_fail, std::size_t off, auto value) {
    std::string b = base;
    std::memcpy(&b[off], &value, sizeof value);
    add_bytes(name, must_fail, b);
  };
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  patch("sizeof_hdr 0", true, 0, std::int32_t(0));
  patch("sizeof_hdr 540", true, 0, std::int32_t(540));
  for (short v : {0, -1, 9}) patch("dim[0] " + std::to_string(v), true, 40, std::int16_t(v));
  for (short v : {0, -16, 32767, 32}) patch("dim[1] " + std::to_string(v), true, 42, std::int16_t(v));
  for (short v : {0, -8, 16}) patch("dim[3] " + std::to_string(v), true, 46, std::int16_t(v));
  {
    std::string b = base;
    const std::int16_t four = 4, two = 2;
    std::memcpy(&b[40], &four, 2), std::memcpy(&b[48], &two, 2);
    add_bytes("4-D, two volumes", true, b);
  }
  for (short v : {0, 32, 128, 2304, 1792, 999, 16}) patch("datatype " + std::to_string(v), true, 70, std::int16_t(v));
  for (short v : {0, 7, 64}) patch("bitpix " + std::to_string(v), true, 72, std::int16_t(v));
  for (int axis = 1; axis <= 3; ++axis)
    for (float v : {0.0f, nan, inf, 1e30f})
      patch("pixdim[" + std::to_string(axis) + "] " + std::to_string(v), true, std::size_t(76 + 4 * axis), v);
  for (float v : {0.0f, 10.0f, 1e9f, -1.0f, nan, 353.0f}) patch("vox_offset " + std::to_string(v), true, 108, v);
  for (float v : {inf, 1e30f}) patch("scl_slope " + std::to_string(v), true, 112, v);
  for (float v : {nan, inf}) patch("scl_inter " + std::to_string(v), true, 116, v);
  for (std::size_t off : {280u, 296u, 312u}) patch("srow NaN at " + std::to_string(off), true, off, nan);
  {
    std::string b = base;
    std::memset(&b[280], 0, 48);
    add_bytes("sform all zero (singular)", true, b);
  }
  {
    std::string b = base;
    const std::int16_t one = 1, zero = 0;
    std::memcpy(&b[252], &one, 2), std::memcpy(&b[254], &zero, 2);
    for (const auto& [off, v, what] : {std::tuple{256u, nan, "quatern_b NaN"}, std::tuple{256u, 2.0f, "quatern_b 2"},
                                       std::tuple{268u, nan, "qoffset_x NaN"}}) {
      std::string c = b;
      std::memcpy(&c[off], &v, 4);
      add_bytes(std::string("qform only, ") + what, true, c);
    }
  }
  patch("magic xx1", true, 344, std::array<char, 4>{'x', 'x', '1', '\0'});
  patch("magic ni1 (a header for a separate .img)", true, 344, std::array<char, 4>{'n', 'i', '1', '\0'});
  for (int t = 0; t < 10; ++t) {
    const std::size_t at = std::uniform_int_distribution<std::size_t>(0, base.size() - 1)(rng);
    add_bytes("cut at byte " + std::to_string(at), true, base.substr(0, at));
  }
  for (int t = 0; t < 15; ++t) {
    std::string b = base;
    for (int k = 0; k < 3; ++k) b[std::uniform_int_distribution<std::size_t>(0, 347)(rng)] = char(rng());
    add_bytes("3 header bytes changed", false, b);
  }
  // Compressed: the stream cut, changed, followed by junk, or empty.
  auto gz = [](const std::string& raw) {
    uLongf len = compressBound(uLong(raw.size())) + 32;
    std::string out(len, '\0');
    z_stream s{};
    deflateInit2(&s, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);
    s.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(raw.data()));
    s.avail_in = uInt(raw.size());
    s.next_out = reinterpret_cast<Bytef*>(out.data());
    s.avail_out = uInt(out.size());
    deflate(&s, Z_FINISH);
    out.resize(s.total_out);
    deflateEnd(&s);
    return out;
  };
  const std::string z = gz(base);
  add_bytes(".nii.gz holding half its stream", true, z.substr(0, z.size() / 2), ".nii.gz");
  add_bytes(".nii.gz short of its last 9 bytes", true, z.substr(0, z.size() - 9), ".nii.gz");
  {
    std::string c = z;
    c[c.size() / 2] = char(c[c.size() / 2] ^ 0x5A);
    add_bytes(".nii.gz with a changed byte mid-stream", true, c, ".nii.gz");
  }
  add_bytes(".nii.gz followed by junk", false, z + "junkjunk", ".nii.gz");
  add_bytes("an empty .nii.gz", true, "", ".nii.gz");
  add_bytes("a .nii.gz that is not compressed", false, base, ".nii.gz");
  return cases;
}

std::vector<CorpusCase> text_header_corpus(const fs::path& root, std::mt19937& rng) {
  std::string data(16 * 16 * 8 * 2, '\0');
  for (std::size_t i = 0; i < data.size(); i += 2) data[i] = char(i % 91);
  const std::vector<std::pair<std::string, std::string>> nrrd = {
      {"type", "short"}, {"dimension", "3"}, {"space", "left-posterior-superior"}, {"sizes", "16 16 8"},
      {"space directions", "(1,0,0) (0,1,0) (0,0,2)"}, {"space origin", "(0,0,0)"}, {"endian", "little"},
      {"encoding", "raw"}};
  const std::vector<std::pair<std::string, std::string>> mha = {
      {"ObjectType", "Image"}, {"NDims", "3"}, {"DimSize", "16 16 8"}, {"ElementType", "MET_SHORT"},
      {"ElementSpacing", "1 1 2"}, {"Offset", "0 0 0"}, {"TransformMatrix", "1 0 0 0 1 0 0 0 1"},
      {"BinaryData", "True"}, {"BinaryDataByteOrderMSB", "False"}, {"ElementDataFile", "LOCAL"}};
  auto render = [&](bool is_nrrd, const std::string& key, const std::string& value, bool drop) {
    std::string h = is_nrrd ? "NRRD0004\n" : "";
    for (const auto& [k, v] : is_nrrd ? nrrd : mha) {
      const bool hit = k == key;
      if (hit && drop) continue;
      h += k + (is_nrrd ? ": " : " = ") + (hit ? value : v) + "\n";
    }
    return h + (is_nrrd ? "\n" : "") + data;
  };
  std::vector<CorpusCase> cases;
  int n = 0;
  auto add = [&](bool is_nrrd, const std::string& name, bool must_fail, const std::string& bytes) {
    const fs::path f = root / ("c" + std::to_string(n++) + (is_nrrd ? ".nrrd" : ".mha"));
    write_bytes(f, bytes);
    cases.push_back({"text-header", (is_nrrd ? "NRRD " : "MHA ") + name, "info " + quoted(f), f, {}, f, must_fail});
  };
  const std::vector<std::pair<std::string, std::vector<std::string>>> nrrd_bad = {
      {"sizes", {"0 16 8", "-1 16 8", "16 16", "99999 99999 99999", "16 16 80"}},
      {"type", {"complex", "uchar4", ""}},
      {"dimension", {"4", "0", "2"}},
      {"encoding", {"rot13", "gzip", "bzip2"}},
      {"endian", {"middle"}},
      {"space directions", {"(0,0,0) (0,1,0) (0,0,2)", "(nan,0,0) (0,1,0) (0,0,2)", "(1,0,0) (0,1,0)"}},
      {"space origin", {"(nan,0,0)"}},
      {"byte skip", {"99999999"}},
      {"data file", {"missing.raw"}}};
  for (const auto& [key, values] : nrrd_bad)
    for (const auto& v : values) {
      std::string text = render(true, key, v, false);
      if (key == "byte skip" || key == "data file")  // not in the base header: insert after the magic
        text.insert(9, key + ": " + v + "\n");
      add(true, key + ": " + v, true, text);
    }
  add(true, "no sizes", true, render(true, "sizes", "", true));
  add(true, "magic NRRD9999", true, "NRRD9999" + render(true, "", "", false).substr(8));
  const std::vector<std::pair<std::string, std::vector<std::string>>> mha_bad = {
      {"DimSize", {"0 16 8", "16 16", "16 16 80", "99999 99999 99999"}},
      {"ElementType", {"MET_FOO", "MET_SHORT_ARRAY"}},
      {"ElementSpacing", {"0 1 1", "nan 1 1"}},
      {"NDims", {"4", "0"}},
      {"ElementDataFile", {"missing.raw", "LIST"}},
      {"TransformMatrix", {"0 0 0 0 0 0 0 0 0", "nan 0 0 0 1 0 0 0 1"}}};
  for (const auto& [key, values] : mha_bad)
    for (const auto& v : values) add(false, key + " = " + v, true, render(false, key, v, false));
  add(false, "no DimSize", true, render(false, "DimSize", "", true));
  add(false, "CompressedData = True over raw data", true,
      "CompressedData = True\n" + render(false, "", "", false));
  add(false, "HeaderSize = 99999999 (ignored before LOCAL data)", false, "HeaderSize = 99999999\n" + render(false, "", "", false));
  for (bool is_nrrd : {true, false}) {
    const std::string whole = render(is_nrrd, "", "", false);
    for (int t = 0; t < 5; ++t) {
      const std::size_t at = std::uniform_int_distribution<std::size_t>(0, whole.size() - 1)(rng);
      add(is_nrrd, "cut at byte " + std::to_string(at), true, whole.substr(0, at));
    }
  }
  return cases;
}

}  // namespace organsmith::testing
