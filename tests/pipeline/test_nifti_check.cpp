// Corrupt NIfTI files are refused before ITK reads them (ITK aborts on some, reads others as
// garbage): each kind with its exit code, a message naming the file, and no crash.

#include "core/errors.h"
#include "pipeline/io/image_io.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>

using namespace organsmith;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
namespace fs = std::filesystem;

namespace {

std::string bytes_of(const fs::path& p) { return organsmith::testing::read_file(p); }

void write_bytes(const fs::path& p, const std::string& b) { std::ofstream(p, std::ios::binary) << b; }

template <typename T>
void put(std::string& b, std::size_t offset, T v) {
  std::memcpy(b.data() + offset, &v, sizeof v);
}

}  // namespace

TEST(NiftiCheck, CorruptHeadersAndDataAreRefusedWithTheirCodes) {
  ScratchDir tmp("nifti-check");
  Volume v;
  v.grid.size_vox = {16, 16, 8};
  v.grid.spacing_mm = {1.5, 1.5, 3.0};
  v.hu.assign(std::size_t(v.grid.voxel_count()), 40.0f);
  write_volume_file(v, tmp / "good.nii");
  const std::string good = bytes_of(tmp / "good.nii");
  ASSERT_GT(good.size(), 352u);
  std::string log;
  ASSERT_EQ(run_cli("info " + (tmp / "good.nii").string(), &log), 0) << log;

  struct Case {
    const char* name;
    std::function<void(std::string&)> corrupt;
    ExitCode expected;
  };
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  const std::vector<Case> cases = {
      {"pixdim_nan", [&](std::string& b) { put<float>(b, 80, nan); }, ExitCode::bad_geometry},
      {"pixdim_zero", [&](std::string& b) { put<float>(b, 84, 0.0f); }, ExitCode::bad_geometry},
      {"sform_inf", [&](std::string& b) { put<std::int16_t>(b, 254, 1), put<float>(b, 280, inf); }, ExitCode::bad_geometry},
      {"qform_nan", [&](std::string& b) { put<std::int16_t>(b, 252, 1), put<float>(b, 256, nan); }, ExitCode::bad_geometry},
      {"dim_negative", [&](std::string& b) { put<std::int16_t>(b, 42, -16); }, ExitCode::unsupported_input},
      {"dim_zero", [&](std::string& b) { put<std::int16_t>(b, 44, 0); }, ExitCode::unsupported_input},
      {"four_d", [&](std::string& b) { put<std::int16_t>(b, 40, 4), put<std::int16_t>(b, 48, 3); }, ExitCode::unsupported_input},
      {"complex64", [&](std::string& b) { put<std::int16_t>(b, 70, 32), put<std::int16_t>(b, 72, 64); }, ExitCode::unsupported_input},
      {"rgb24", [&](std::string& b) { put<std::int16_t>(b, 70, 128), put<std::int16_t>(b, 72, 24); }, ExitCode::unsupported_input},
      {"vox_offset_huge", [&](std::string& b) { put<float>(b, 108, 1e9f); }, ExitCode::corrupt_file},
      {"header_32_cubed", [&](std::string& b) {
         put<std::int16_t>(b, 42, 32), put<std::int16_t>(b, 44, 32), put<std::int16_t>(b, 46, 32);
       }, ExitCode::corrupt_file},
      {"huge_plane_tiny_data", [&](std::string& b) {
         put<std::int16_t>(b, 40, 3), put<std::int16_t>(b, 42, 32767), put<std::int16_t>(b, 44, 32767), put<std::int16_t>(b, 46, 1);
       }, ExitCode::corrupt_file},
      {"truncated_data", [&](std::string& b) { b.resize(b.size() - 1000); }, ExitCode::corrupt_file},
      {"truncated_header", [&](std::string& b) { b.resize(200); }, ExitCode::corrupt_file},
      {"not_nifti", [&](std::string& b) { put<std::int32_t>(b, 0, 1234); }, ExitCode::unsupported_input},
  };
  for (const auto& c : cases) {
    std::string b = good;
    c.corrupt(b);
    const fs::path f = tmp / (std::string(c.name) + ".nii");
    write_bytes(f, b);
    EXPECT_EQ(run_cli("info " + f.string(), &log), int(c.expected)) << c.name << "\n" << log;
    EXPECT_NE(log.find(f.filename().string()), std::string::npos) << c.name << ": names the file\n" << log;
  }

  // A .nii.gz holding half its gzip stream.
  write_volume_file(v, tmp / "good.nii.gz");
  const std::string gz = bytes_of(tmp / "good.nii.gz");
  write_bytes(tmp / "half.nii.gz", gz.substr(0, gz.size() / 2));
  EXPECT_EQ(run_cli("info " + (tmp / "half.nii.gz").string(), &log), int(ExitCode::corrupt_file)) << log;
  EXPECT_EQ(run_cli("info " + (tmp / "good.nii.gz").string(), &log), 0) << log;

  // The memory a volume needs is refused from its header, before anything is allocated.
  Volume big;
  big.grid.size_vox = {256, 256, 64};
  big.grid.spacing_mm = {1, 1, 1};
  big.hu.assign(std::size_t(big.grid.voxel_count()), 0.0f);
  write_volume_file(big, tmp / "big.nii");
  EXPECT_EQ(run_cli("info " + (tmp / "big.nii").string() + " --max-memory-mb 10", &log), int(ExitCode::too_large)) << log;
  EXPECT_EQ(run_cli("info " + (tmp / "big.nii").string() + " --max-memory-mb 200", &log), 0) << log;
}
