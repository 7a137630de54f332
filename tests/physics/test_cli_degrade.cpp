// `organsmith degrade` as a user runs it: files, byte-identical reruns, τ_D fit, exit codes.

#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using organsmith::testing::read_file;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;

namespace {

std::string q(const fs::path& p) { return "'" + p.string() + "'"; }

}  // namespace

TEST(DegradeCli, WritesStagesMassAndSummaryByteIdentically) {
  ScratchDir s("degrade-cli");
  std::string log;
  ASSERT_EQ(run_cli("degrade --out " + q(s.path() / "a") + " --elements 60", &log), 0) << log;
  ASSERT_EQ(run_cli("degrade --out " + q(s.path() / "b") + " --elements 60", &log), 0) << log;
  std::size_t files = 0, pngs = 0;
  for (const auto& e : fs::recursive_directory_iterator(s.path() / "a")) {
    if (!e.is_regular_file()) continue;
    ++files;
    const fs::path rel = fs::relative(e.path(), s.path() / "a");
    const std::string bytes = read_file(e.path());
    EXPECT_TRUE(bytes == read_file(s.path() / "b" / rel)) << rel << " differs between two runs";
    if (e.path().extension() == ".png") {
      ++pngs;
      EXPECT_EQ(bytes.rfind("\x89PNG", 0), 0u) << rel;
    }
  }
  // original, 6 stages, mass.csv, summary.json, manifest.json (what organsmith wrote there);
  // pictures: 5 stages (Fig. 6.8), energy map, mass.
  EXPECT_EQ(files, 17u);
  EXPECT_EQ(pngs, 7u);
  EXPECT_TRUE(fs::exists(s.path() / "a" / "snapshots" / "plot_degradation_stage_5.png"));
  const auto j = nlohmann::json::parse(read_file(s.path() / "a" / "summary.json"));
  ASSERT_EQ(j["stages"].size(), 6u);
  EXPECT_EQ(j["stages"][1]["previous"], "stage_0_0.0w.vtp");
  EXPECT_DOUBLE_EQ(j["stages"][5]["t_days"].get<double>(), 17.5);
  for (const auto& st : j["stages"]) {
    const std::string vtp = read_file(s.path() / "a" / st["file"].get<std::string>());
    EXPECT_NE(vtp.find("Name=\"d\""), std::string::npos);
    EXPECT_NE(vtp.find("Name=\"E_star\""), std::string::npos);
    EXPECT_NE(vtp.find("NumberOfLines=\"60\""), std::string::npos);
  }
  const std::string mass = read_file(s.path() / "a" / "mass.csv");
  EXPECT_EQ(mass.rfind("t_days,mass_fraction,", 0), 0u);
  // The mass curve it wrote calibrates back to the τ_D it was made with.
  ASSERT_EQ(run_cli("degrade --fit " + q(s.path() / "a" / "mass.csv") + " --out " + q(s.path() / "fit") + " --elements 60", &log), 0) << log;
  const auto fit = nlohmann::json::parse(read_file(s.path() / "fit" / "fit.json"));
  EXPECT_NEAR(fit["tau_d"].get<double>() / 241.41, 1.0, 2e-3);
  EXPECT_GT(fit["r2"].get<double>(), 0.999);
}

TEST(DegradeCli, BadInputGivesDocumentedExitCodes) {
  ScratchDir s("degrade-cli");
  std::string log;
  EXPECT_EQ(run_cli("degrade --out " + q(s.path() / "neg") + " --tau-d -3", &log), 2) << log;
  EXPECT_FALSE(fs::exists(s.path() / "neg"));
  // A clip whose legs end above the tissue.
  std::string preset;
  ASSERT_EQ(run_cli("degrade --print-clip", &preset), 0);
  const auto p = preset.find("leg_length_mm = 2.5");
  ASSERT_NE(p, std::string::npos);
  preset.replace(p, 19, "leg_length_mm = 0.3");
  std::ofstream(s.path() / "short.toml") << preset;
  EXPECT_EQ(run_cli("degrade --out " + q(s.path() / "x") + " --clip " + q(s.path() / "short.toml"), &log), 20) << log;
  EXPECT_NE(log.find("miss the tissue"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(s.path() / "x"));
  // A mass series that rises.
  std::ofstream(s.path() / "up.csv") << "t_days,mass_fraction\n1,0.95\n3,0.80\n7,0.97\n";
  EXPECT_EQ(run_cli("degrade --fit " + q(s.path() / "up.csv") + " --out " + q(s.path() / "f"), &log), 21) << log;
  EXPECT_NE(log.find("line 4"), std::string::npos) << log;
  // No load: τ_D cannot be identified.
  std::ofstream(s.path() / "ok.csv") << "t_days,mass_fraction\n1,0.97\n3,0.92\n7,0.83\n";
  EXPECT_EQ(run_cli("degrade --fit " + q(s.path() / "ok.csv") + " --out " + q(s.path() / "f") + " --load-n 0", &log), 2) << log;
  EXPECT_EQ(run_cli("degrade --fit " + q(s.path() / "missing.csv") + " --out " + q(s.path() / "f"), &log), 3) << log;
  EXPECT_FALSE(fs::exists(s.path() / "f"));
}
