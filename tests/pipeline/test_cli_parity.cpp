// The single-stage commands are the stages of `run`: `segment`, then `mesh DIR`, `guide DIR` and
// `snapshot DIR` leave the same files, byte for byte, as `organsmith run` of the same case.

#include "core/sha256.h"
#include "test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>

using organsmith::sha256_file;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
namespace fs = std::filesystem;

namespace {

std::string q(const fs::path& p) { return "'" + p.string() + "'"; }

/// SHA-256 of every file under `dir` but the manifest (it records times), by relative path.
std::map<std::string, std::string> digests(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename() != "manifest.json")
      out[fs::relative(e.path(), dir).generic_string()] = sha256_file(e.path());
  return out;
}

}  // namespace

TEST(CliParity, SegmentMeshGuideSnapshotWriteWhatRunWrites) {
  ScratchDir tmp("cli-parity");
  std::string log;
  ASSERT_EQ(run_cli("phantom --out " + q(tmp / "ph") + " --size 256 --seed 1", &log), 0) << log;
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
  ASSERT_EQ(run_cli("run " + q(tmp / "case.toml") + " --out " + q(a), &log), 0) << log;

  // The same, stage by stage, into b/parity (the case name is the folder's name).
  std::string seed_flag = std::string("--seed=") + seed;
  seed_flag.erase(std::remove(seed_flag.begin(), seed_flag.end(), ' '), seed_flag.end());
  ASSERT_EQ(run_cli("segment " + q(tmp / "ph" / "dicom") + " --out " + q(b) + " --organ gallbladder " + seed_flag +
                        " --organ trachea",
                    &log),
            0)
      << log;
  ASSERT_EQ(run_cli("mesh " + q(b) + " --edge-mm 3 --allow-quality-failures", &log), 0) << log;
  ASSERT_EQ(run_cli("guide " + q(b), &log), 0) << log;
  ASSERT_EQ(run_cli("snapshot " + q(b) + " --views organs,slices --size 320x240", &log), 0) << log;

  const auto da = digests(a), db = digests(b);
  EXPECT_GT(da.size(), 30u);
  for (const auto& [path, sha] : da) {
    ASSERT_TRUE(db.count(path)) << path << " written by run only";
    EXPECT_EQ(db.at(path), sha) << path << " differs";
  }
  for (const auto& [path, _] : db) EXPECT_TRUE(da.count(path)) << path << " written by the commands only";
}
