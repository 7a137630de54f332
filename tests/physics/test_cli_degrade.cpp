// `organsmith degrade` as a user runs it: files, byte-identical reruns, τ_D fit, exit codes.

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

struct Scratch {
  fs::path dir;
  Scratch() {
    dir = fs::temp_directory_path() / ("organsmith_degrade_cli_" + std::to_string(::getpid()) + "_" +
                                       ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~Scratch() { fs::remove_all(dir); }
};

int run(const std::string& args, std::string* out = nullptr) {
  const std::string cmd = std::string("'") + ORGANSMITH_CLI + "' " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  std::string text;
  char buf[4096];
  while (std::size_t n = std::fread(buf, 1, sizeof buf, p)) text.append(buf, n);
  const int status = pclose(p);
  if (out) *out = text;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string q(const fs::path& p) { return "'" + p.string() + "'"; }

}  // namespace

TEST(DegradeCli, WritesStagesMassAndSummaryByteIdentically) {
  Scratch s;
  std::string log;
  ASSERT_EQ(run("degrade --out " + q(s.dir / "a") + " --elements 60", &log), 0) << log;
  ASSERT_EQ(run("degrade --out " + q(s.dir / "b") + " --elements 60", &log), 0) << log;
  std::size_t files = 0, pngs = 0;
  for (const auto& e : fs::recursive_directory_iterator(s.dir / "a")) {
    if (!e.is_regular_file()) continue;
    ++files;
    const fs::path rel = fs::relative(e.path(), s.dir / "a");
    const std::string bytes = slurp(e.path());
    EXPECT_TRUE(bytes == slurp(s.dir / "b" / rel)) << rel << " differs between two runs";
    if (e.path().extension() == ".png") {
      ++pngs;
      EXPECT_EQ(bytes.rfind("\x89PNG", 0), 0u) << rel;
    }
  }
  // original, 6 stages, mass.csv, summary.json; pictures: 5 stages (Fig. 6.8), energy map, mass.
  EXPECT_EQ(files, 16u);
  EXPECT_EQ(pngs, 7u);
  EXPECT_TRUE(fs::exists(s.dir / "a" / "snapshots" / "plot_degradation_stage_5.png"));
  const auto j = nlohmann::json::parse(slurp(s.dir / "a" / "summary.json"));
  ASSERT_EQ(j["stages"].size(), 6u);
  EXPECT_EQ(j["stages"][1]["previous"], "stage_0_0.0w.vtp");
  EXPECT_DOUBLE_EQ(j["stages"][5]["t_days"].get<double>(), 17.5);
  for (const auto& st : j["stages"]) {
    const std::string vtp = slurp(s.dir / "a" / st["file"].get<std::string>());
    EXPECT_NE(vtp.find("Name=\"d\""), std::string::npos);
    EXPECT_NE(vtp.find("Name=\"E_star\""), std::string::npos);
    EXPECT_NE(vtp.find("NumberOfLines=\"60\""), std::string::npos);
  }
  const std::string mass = slurp(s.dir / "a" / "mass.csv");
  EXPECT_EQ(mass.rfind("t_days,mass_fraction,", 0), 0u);
  // The mass curve it wrote calibrates back to the τ_D it was made with.
  ASSERT_EQ(run("degrade --fit " + q(s.dir / "a" / "mass.csv") + " --out " + q(s.dir / "fit") + " --elements 60", &log), 0) << log;
  const auto fit = nlohmann::json::parse(slurp(s.dir / "fit" / "fit.json"));
  EXPECT_NEAR(fit["tau_d"].get<double>() / 241.41, 1.0, 2e-3);
  EXPECT_GT(fit["r2"].get<double>(), 0.999);
}

TEST(DegradeCli, BadInputGivesDocumentedExitCodes) {
  Scratch s;
  std::string log;
  EXPECT_EQ(run("degrade --out " + q(s.dir / "neg") + " --tau-d -3", &log), 2) << log;
  EXPECT_FALSE(fs::exists(s.dir / "neg"));
  // A clip whose legs end above the tissue.
  std::string preset;
  ASSERT_EQ(run("degrade --print-clip", &preset), 0);
  const auto p = preset.find("leg_length_mm = 2.5");
  ASSERT_NE(p, std::string::npos);
  preset.replace(p, 19, "leg_length_mm = 0.3");
  std::ofstream(s.dir / "short.toml") << preset;
  EXPECT_EQ(run("degrade --out " + q(s.dir / "x") + " --clip " + q(s.dir / "short.toml"), &log), 20) << log;
  EXPECT_NE(log.find("miss the tissue"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(s.dir / "x"));
  // A mass series that rises.
  std::ofstream(s.dir / "up.csv") << "t_days,mass_fraction\n1,0.95\n3,0.80\n7,0.97\n";
  EXPECT_EQ(run("degrade --fit " + q(s.dir / "up.csv") + " --out " + q(s.dir / "f"), &log), 21) << log;
  EXPECT_NE(log.find("line 4"), std::string::npos) << log;
  // No load: τ_D cannot be identified.
  std::ofstream(s.dir / "ok.csv") << "t_days,mass_fraction\n1,0.97\n3,0.92\n7,0.83\n";
  EXPECT_EQ(run("degrade --fit " + q(s.dir / "ok.csv") + " --out " + q(s.dir / "f") + " --load-n 0", &log), 2) << log;
  EXPECT_EQ(run("degrade --fit " + q(s.dir / "missing.csv") + " --out " + q(s.dir / "f"), &log), 3) << log;
  EXPECT_FALSE(fs::exists(s.dir / "f"));
}
