// The physics subcommands as a user runs them: outputs, determinism, exit codes.

#include "physics/materials/calibration.h"
#include "physics/materials/models.h"

#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace fs = std::filesystem;
using organsmith::testing::read_file;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
using namespace organsmith::physics;

namespace {

void write_wall_csv(const fs::path& path) {
  const auto m = make_model("fung-wall");
  const std::vector<double> p = {19.11, 17.06, 18.25, 6.59};  // Table 5.1.1 mean
  Rng rng(3);
  std::ofstream f(path);
  f << "specimen,direction,stretch,stress_pa\n";
  for (LoadCase l : {LoadCase::uniaxial_circumferential, LoadCase::uniaxial_longitudinal})
    for (int i = 1; i <= 30; ++i) {
      const LoadPoint pt{1.0 + 0.01 * i, 1.0, l};
      f << "S1," << (l == LoadCase::uniaxial_circumferential ? "circumferential" : "longitudinal") << ','
        << pt.x << ',' << m->respond_one(pt, p) * (1 + 0.02 * rng.normal()) << '\n';
    }
}

}  // namespace

TEST(PhysicsCli, CalibrateWritesParamsAndFitDeterministically) {
  ScratchDir s("physics-cli");
  write_wall_csv(s.path() / "wall.csv");
  std::string log;
  ASSERT_EQ(run_cli("calibrate --model fung-wall --data '" + (s.path() / "wall.csv").string() + "' --out '" +
                (s.path() / "a").string() + "' --seed 5 --residuals relative", &log), 0) << log;
  ASSERT_EQ(run_cli("calibrate --model fung-wall --data '" + (s.path() / "wall.csv").string() + "' --out '" +
                (s.path() / "b").string() + "' --seed 5 --residuals relative", &log), 0) << log;
  EXPECT_EQ(read_file(s.path() / "a" / "fit.csv"), read_file(s.path() / "b" / "fit.csv"));
  auto j = nlohmann::json::parse(read_file(s.path() / "a" / "params.json"));
  auto k = nlohmann::json::parse(read_file(s.path() / "b" / "params.json"));
  EXPECT_EQ(j["parameters"], k["parameters"]) << "same seed, same parameters";
  EXPECT_EQ(j["model"], "fung-wall");
  EXPECT_EQ(j["seed"], 5);
  EXPECT_EQ(j["points"], 60);
  EXPECT_GT(j["r2"].get<double>(), 0.98);
  for (const char* key : {"sse", "rmse", "seconds"}) EXPECT_TRUE(j.contains(key)) << key;
  ASSERT_EQ(j["parameters"].size(), 4u);
  EXPECT_EQ(j["parameters"][0]["name"], "c");
  EXPECT_EQ(j["parameters"][0]["unit"], "Pa");
  EXPECT_TRUE(j["parameters"][0].contains("lower") && j["parameters"][0].contains("upper"));
  // a1, a2, a4 are not identifiable from uniaxial strips: no standard error is claimed for them.
  EXPECT_TRUE(j["parameters"][1]["standard_error"].is_null());
  const std::string fit = read_file(s.path() / "a" / "fit.csv");
  EXPECT_EQ(fit.substr(0, fit.find('\n')), "specimen,load,stretch,lateral_stretch,stress_pa,model_stress_pa,residual_pa");
  EXPECT_EQ(std::count(fit.begin(), fit.end(), '\n'), 61);
}

TEST(PhysicsCli, BadDataExitsWithCalibrationCodeAndWritesNothing) {
  ScratchDir s("physics-cli");
  std::ofstream(s.path() / "bad.csv") << "stretch,stress_pa\n1.1,10\n1.2,nan\n1.3,40\n1.4,50\n1.5,70\n1.6,80\n";
  std::string log;
  EXPECT_EQ(run_cli("calibrate --model fung-wall --data '" + (s.path() / "bad.csv").string() + "' --out '" +
                (s.path() / "o").string() + "'", &log), 21) << log;
  EXPECT_NE(log.find("bad.csv:3, column 'stress_pa'"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(s.path() / "o"));
  write_wall_csv(s.path() / "wall.csv");
  EXPECT_EQ(run_cli("calibrate --model fung-wall --data '" + (s.path() / "wall.csv").string() + "' --out '" +
                (s.path() / "o").string() + "' --lower 1,1,1,0 --upper 100,50,0.5,20", &log), 2) << log;
  EXPECT_NE(log.find("inverted bounds for a2"), std::string::npos) << log;
  EXPECT_EQ(run_cli("calibrate --model nonsense --data '" + (s.path() / "wall.csv").string() + "' --out '" +
                (s.path() / "o").string() + "'", &log), 2) << log;
  EXPECT_FALSE(fs::exists(s.path() / "o"));
  // A directory given as the data file: exit 3 naming it (no internal error from the stream).
  fs::create_directories(s.path() / "data_dir");
  EXPECT_EQ(run_cli("calibrate --model fung-wall --data '" + (s.path() / "data_dir").string() + "' --out '" +
                (s.path() / "o").string() + "'", &log), 3) << log;
  EXPECT_NE(log.find("data_dir"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(s.path() / "o"));
  // A file far larger than any test series (sparse: no disk used) is refused before it is read.
  std::ofstream(s.path() / "huge.csv") << "stretch,stress_pa\n";
  fs::resize_file(s.path() / "huge.csv", std::uintmax_t(1) << 30);
  EXPECT_EQ(run_cli("calibrate --model fung-wall --data '" + (s.path() / "huge.csv").string() + "' --out '" +
                (s.path() / "o").string() + "'", &log), 21) << log;
  EXPECT_NE(log.find("huge.csv"), std::string::npos) << log;
  EXPECT_NE(log.find("limit of 64 MiB"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(s.path() / "o"));
}

// What a spreadsheet program saves: a UTF-8 byte-order mark first and CRLF line ends. The fit is
// the one of the same data without them.
TEST(PhysicsCli, CalibrationDataWithAByteOrderMarkFitsAsWithout) {
  ScratchDir s("physics-cli-bom");
  write_wall_csv(s.path() / "wall.csv");
  std::string plain = read_file(s.path() / "wall.csv"), excel = "\xEF\xBB\xBF";
  for (char c : plain) excel += c == '\n' ? std::string("\r\n") : std::string(1, c);
  std::ofstream(s.path() / "excel.csv", std::ios::binary) << excel;
  std::string log;
  for (const char* name : {"wall", "excel"})
    ASSERT_EQ(run_cli(std::string("calibrate --model fung-wall --data '") + (s.path() / (std::string(name) + ".csv")).string() +
                          "' --out '" + (s.path() / name).string() + "'", &log), 0) << log;
  const auto a = nlohmann::json::parse(read_file(s.path() / "wall" / "params.json"));
  const auto b = nlohmann::json::parse(read_file(s.path() / "excel" / "params.json"));
  ASSERT_EQ(a["parameters"].size(), b["parameters"].size());
  for (std::size_t k = 0; k < a["parameters"].size(); ++k)
    EXPECT_EQ(a["parameters"][k]["value"], b["parameters"][k]["value"]) << a["parameters"][k]["name"];
}

TEST(PhysicsCli, MaterialsListsThesisTables) {
  std::string out;
  ASSERT_EQ(run_cli("materials --json", &out), 0) << out;
  const auto j = nlohmann::json::parse(out);
  EXPECT_GE(j["materials"].size(), 10u);
  EXPECT_EQ(j["regions"]["gallbladder_body"], "fung-organ/table-5.1.2/mean");
  ASSERT_EQ(run_cli("materials", &out), 0);
  EXPECT_NE(out.find("Table 4.2.2"), std::string::npos);
}

TEST(PhysicsCli, UncertaintyMonteCarloAndImvfosm) {
  ScratchDir s("physics-cli");
  std::string log;
  ASSERT_EQ(run_cli("uncertainty --method mc --samples 2000 --out '" + (s.path() / "mc").string() + "'", &log), 0) << log;
  const std::string cdf = read_file(s.path() / "mc" / "cdf.csv");
  EXPECT_EQ(cdf.substr(0, cdf.find('\n')), "stretch,probability,stress_pa");
  EXPECT_EQ(std::count(cdf.begin(), cdf.end(), '\n'), 1 + 7 * 101);
  const auto j = nlohmann::json::parse(read_file(s.path() / "mc" / "summary.json"));
  EXPECT_EQ(j["stretches"].size(), 7u);
  ASSERT_EQ(run_cli("uncertainty --method imvfosm --derivatives printed --out '" + (s.path() / "im").string() + "'", &log), 0) << log;
  const auto k = nlohmann::json::parse(read_file(s.path() / "im" / "imvfosm.json"));
  EXPECT_EQ(k["sigma"].size(), 7u);
}
