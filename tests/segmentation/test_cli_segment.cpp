// `organsmith segment` as a user runs it: outputs, exit codes, nothing written on bad input.

#include "tests/support/test_support.h"
#include "core/errors.h"
#include "pipeline/io/image_io.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <fstream>

using namespace organsmith;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
namespace fs = std::filesystem;

namespace {

std::string seed_arg(const nlohmann::json& seeds, const std::string& organ) {
  const auto& s = seeds["seeds_lps_mm"][organ];
  char b[128];
  std::snprintf(b, sizeof b, "--seed=%.4f,%.4f,%.4f", s[0].get<double>(), s[1].get<double>(), s[2].get<double>());
  return b;
}

}  // namespace

TEST(SegmentCli, BothOrgansOnThePhantomWriteLabelsContoursAndOverlays) {
  ScratchDir tmp("seg_cli");
  const auto ph = run_cli("phantom --out " + (tmp / "ph").string() + " --size 256");
  ASSERT_EQ(ph.exit_code, 0) << ph.output;
  const nlohmann::json seeds = nlohmann::json::parse(std::ifstream(tmp / "ph/seeds.json"));
  const fs::path out = tmp / "seg";
  const auto r = run_cli("segment " + (tmp / "ph/dicom").string() + " --out " + out.string() +
                         " --organ gallbladder " + seed_arg(seeds, "gallbladder") + " --organ trachea");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The files of the run's ingest and segment stages (the command is those stages of `run`).
  for (const char* f : {"labels.nii.gz", "contours_gallbladder.json", "contours_trachea.json",
                        "overlays/overlay_gallbladder.png", "overlays/overlay_trachea.png", "ingest.json", "manifest.json"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  const LabelMap labels = read_label_map(out / "labels.nii.gz");
  const LabelMap truth = read_label_map(tmp / "ph/ground_truth.nii.gz");
  EXPECT_TRUE(labels.grid.same_geometry(truth.grid));
  EXPECT_GT(labels.count(1), 0);
  EXPECT_GT(labels.count(2), 0);
  EXPECT_LT(labels.count(1) + labels.count(2), labels.grid.voxel_count() / 20);
  // Contour points are LPS mm inside the image and on their slice's plane.
  const nlohmann::json c = nlohmann::json::parse(std::ifstream(out / "contours_trachea.json"));
  EXPECT_EQ(c["frame"], "LPS");
  ASSERT_FALSE(c["contours"].empty());
  const auto [lo, hi] = labels.grid.bounds_lps_mm();
  for (const auto& ct : c["contours"]) {
    const double z = labels.grid.index_to_lps_mm({0, 0, ct["slice_k"].get<double>()}).z();
    for (const auto& p : ct["points_lps_mm"]) {
      EXPECT_NEAR(p[2].get<double>(), z, 1e-3);
      EXPECT_GE(p[0].get<double>(), lo.x() - 1);
      EXPECT_LE(p[0].get<double>(), hi.x() + 1);
    }
  }
}

TEST(SegmentCli, BadSeedsFailWithTheirExitCodeAndWriteNothing) {
  ScratchDir tmp("seg_cli_bad");
  ASSERT_EQ(run_cli("phantom --out " + (tmp / "ph").string() + " --size 128").exit_code, 0);
  const fs::path out = tmp / "seg";
  // Far outside the image, then in the air beside the patient (the phantom's corner).
  for (const std::string seed : {"--seed=5000,5000,5000", "--seed-ijk 1,1,3"}) {
    const auto r = run_cli("segment " + (tmp / "ph/dicom").string() + " --out " + out.string() +
                           " --organ gallbladder " + seed);
    EXPECT_EQ(r.exit_code, int(ExitCode::bad_seed)) << r.output;
    EXPECT_NE(r.output.find("gallbladder"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("seed"), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out)) << "nothing may be written for a bad seed";
  }
  const auto none = run_cli("segment " + (tmp / "ph/dicom").string() + " --out " + out.string() + " --organ gallbladder");
  EXPECT_EQ(none.exit_code, int(ExitCode::usage)) << none.output;
  const auto unknown = run_cli("segment " + (tmp / "ph/dicom").string() + " --out " + out.string() + " --organ spleen");
  EXPECT_EQ(unknown.exit_code, int(ExitCode::usage)) << unknown.output;
  EXPECT_FALSE(fs::exists(out));
}
