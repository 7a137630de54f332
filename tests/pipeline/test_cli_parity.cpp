// The single-stage commands are the stages of `run`: `segment`, then `mesh DIR`, `guide DIR` and
// `snapshot DIR` leave the same files, byte for byte, as `organsmith run` of the same case.

#include "core/progress.h"
#include "core/sha256.h"
#include "pipeline/io/dicom.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

using organsmith::sha256_file;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
using organsmith::testing::file_digests;
using organsmith::testing::has_staging_leftover;
using organsmith::testing::quoted;
using organsmith::testing::read_json;
namespace fs = std::filesystem;

TEST(CliParity, SegmentMeshGuideSnapshotWriteWhatRunWrites) {
  ScratchDir tmp("cli-parity");
  std::string log;
  ASSERT_EQ(run_cli("phantom --out " + quoted(tmp / "ph") + " --size 256 --seed 1", &log), 0) << log;
  const nlohmann::json seeds = nlohmann::json::parse(std::ifstream(tmp / "ph" / "seeds.json"));
  const auto& s = seeds["seeds_lps_mm"]["gallbladder"];
  char seed[160];
  std::snprintf(seed, sizeof seed, "%.4f, %.4f, %.4f", s[0].get<double>(), s[1].get<double>(), s[2].get<double>());

  // The case, run in one go into a/parity.
  std::ofstream(tmp / "case.toml") << "[case]\nname = \"parity\"\ninput = \"ph/dicom\"\n"
                                   << "[[organ]]\nname = \"gallbladder\"\nseed_lps_mm = [" << seed << "]\n"
                                   << "[[organ]]\nname = \"trachea\"\n"
                                   << "[stages.mesh]\nedge_mm = 3.0\n"
                                   << "[stages.snapshot]\nviews = [\"organs\", \"slices\"]\nwidth_px = 320\nheight_px = 240\n";
  const fs::path a = tmp / "a" / "parity", b = tmp / "b" / "parity";
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(a), &log), 0) << log;

  // The same, stage by stage, into b/parity (the case name is the folder's name).
  std::string seed_flag = std::string("--seed=") + seed;
  seed_flag.erase(std::remove(seed_flag.begin(), seed_flag.end(), ' '), seed_flag.end());
  ASSERT_EQ(run_cli("segment " + quoted(tmp / "ph" / "dicom") + " --out " + quoted(b) + " --organ gallbladder " + seed_flag +
                        " --organ trachea",
                    &log),
            0)
      << log;
  ASSERT_EQ(run_cli("mesh " + quoted(b) + " --edge-mm 3 --allow-quality-failures", &log), 0) << log;
  ASSERT_EQ(run_cli("guide " + quoted(b), &log), 0) << log;
  ASSERT_EQ(run_cli("snapshot " + quoted(b) + " --views organs,slices --size 320x240", &log), 0) << log;

  const auto da = file_digests(a, "manifest.json"), db = file_digests(b, "manifest.json");
  EXPECT_GT(da.size(), 30u);
  for (const auto& [path, sha] : da) {
    ASSERT_TRUE(db.count(path)) << path << " written by run only";
    EXPECT_EQ(db.at(path), sha) << path << " differs";
  }
  for (const auto& [path, _] : db) EXPECT_TRUE(da.count(path)) << path << " written by the commands only";

  // A single-stage command skips its unchanged stage and says how to redo it; --force redoes it,
  // to the same bytes.
  ASSERT_EQ(run_cli("guide " + quoted(b), &log), 0) << log;
  EXPECT_NE(log.find("stage guide: unchanged since the last run, skipped (--force to redo)"), std::string::npos) << log;
  ASSERT_EQ(run_cli("guide " + quoted(b) + " --force", &log), 0) << log;
  EXPECT_NE(log.find("stage guide: running"), std::string::npos) << log;
  EXPECT_EQ(file_digests(b / "paths"), file_digests(a / "paths"));
}

namespace {

/// `run` of `case_file` straight through into A, and `run --until segment` then `run` into B (the
/// mesh stage then reads labels.nii.gz back): every file under meshes/ must be the same, byte for byte.
void expect_meshes_same_straight_and_resumed(const fs::path& case_file, const fs::path& tmp, const std::string& name) {
  SCOPED_TRACE(name);
  const fs::path a = tmp / ("straight-" + name), b = tmp / ("resumed-" + name);
  std::string log;
  ASSERT_EQ(run_cli("run " + quoted(case_file) + " --out " + quoted(a), &log), 0) << log;
  ASSERT_EQ(run_cli("run " + quoted(case_file) + " --out " + quoted(b) + " --until segment", &log), 0) << log;
  ASSERT_EQ(run_cli("run " + quoted(case_file) + " --out " + quoted(b), &log), 0) << log;
  const auto da = file_digests(a / "meshes"), db = file_digests(b / "meshes");
  EXPECT_GE(da.size(), 4u);
  EXPECT_EQ(da, db) << "the meshes differ between the straight and the resumed run";
  std::printf("parity %s: %zu mesh files, %s\n", name.c_str(), da.size(), da == db ? "identical" : "DIFFERENT");
}

}  // namespace

// Real scans: the in-memory hand-over and the file round trip give the mesh stage the same label
// map, so a resumed run meshes what a straight one does: the shared abdomen (gallbladder), the
// shared chest (trachea), and the abdomen resampled to 1 mm slices and written as DICOM whose
// origin single precision cannot hold (the geometry NIfTI's float fields round).
TEST(CliParity, RealScansMeshTheSameStraightOnAndResumed) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const fs::path real = organsmith::testing::real_data_dir();
  ScratchDir tmp("cli-parity-real");
  // A point inside the reference gallbladder (its centroid), LPS mm.
  const std::string gallbladder = "[[organ]]\nname = \"gallbladder\"\nseed_lps_mm = [-64.30, -211.87, 118.02]\n";
  std::ofstream(tmp / "abdomen.toml") << "[case]\ninput = \"" << (real / "abdomen-ct-3mm" / "ct.nii.gz").string() << "\"\n"
                                      << gallbladder;
  expect_meshes_same_straight_and_resumed(tmp / "abdomen.toml", tmp.path(), "abdomen-3mm");
  std::ofstream(tmp / "chest.toml") << "[case]\ninput = \"" << (real / "chest-dicom-8mm" / "dicom").string()
                                    << "\"\n[[organ]]\nname = \"trachea\"\n";
  expect_meshes_same_straight_and_resumed(tmp / "chest.toml", tmp.path(), "chest-8mm");

  // The 1 mm variant: linear between the 3 mm slices, shifted by 0.0137 mm along each axis.
  const organsmith::Volume ct = organsmith::read_volume_file(real / "abdomen-ct-3mm" / "ct.nii.gz");
  organsmith::Volume fine;
  fine.grid = ct.grid;
  const double step = ct.grid.spacing_mm.z();
  fine.grid.size_vox[2] = std::int64_t((ct.grid.size_vox[2] - 1) * step) + 1;
  fine.grid.spacing_mm.z() = 1.0;
  fine.grid.origin_lps_mm += fine.grid.direction_lps * Eigen::Vector3d::Constant(0.0137);
  fine.hu.assign(std::size_t(fine.grid.voxel_count()), 0.0f);
  for (std::int64_t k = 0; k < fine.grid.size_vox[2]; ++k) {
    const double z = double(k) / step;
    const std::int64_t k0 = std::min<std::int64_t>(std::int64_t(z), ct.grid.size_vox[2] - 2);
    const double t = z - double(k0);
    for (std::int64_t j = 0; j < fine.grid.size_vox[1]; ++j)
      for (std::int64_t i = 0; i < fine.grid.size_vox[0]; ++i)
        fine.hu[std::size_t(fine.grid.offset(i, j, k))] =
            float(std::lround((1 - t) * ct.at(i, j, k0) + t * ct.at(i, j, k0 + 1)));
  }
  organsmith::NullProgress quiet;
  organsmith::DicomSeriesIds ids;
  ids.uid_seed = "parity-1mm";
  organsmith::write_dicom_series(fine, tmp / "abdomen-1mm", ids, quiet);
  const organsmith::ImageGrid read_back =
      organsmith::ingest(tmp / "abdomen-1mm", organsmith::IngestOptions{}, quiet).volume.grid;  // what the run sees
  EXPECT_NE(double(float(read_back.origin_lps_mm.x())), read_back.origin_lps_mm.x())
      << "the variant's origin should be one single precision rounds";
  std::ofstream(tmp / "abdomen-1mm.toml") << "[case]\ninput = \"" << (tmp / "abdomen-1mm").string() << "\"\n" << gallbladder;
  expect_meshes_same_straight_and_resumed(tmp / "abdomen-1mm.toml", tmp.path(), "abdomen-1mm-dicom");
}
