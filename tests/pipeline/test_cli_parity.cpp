// The single-stage commands are the stages of `run`: `segment`, then `mesh DIR`, `guide DIR` and
// `snapshot DIR` leave the same files, byte for byte, as `organsmith run` of the same case.

#include "core/sha256.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
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
}
