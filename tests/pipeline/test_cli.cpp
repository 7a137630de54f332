// The organsmith CLI as a user runs it: exit codes for bad inputs with nothing written, no
// patient identifiers in any output, phantom determinism, and the run manifest with stage reuse.

#include "core/errors.h"
#include "core/sha256.h"
#include "pipeline/io/dicom.h"
#include "pipeline/io/image_io.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <map>

using namespace organsmith;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
using organsmith::testing::file_digests;
using organsmith::testing::has_staging_leftover;
using organsmith::testing::quoted;
using organsmith::testing::read_json;
namespace fs = std::filesystem;

namespace {




/// A small volume written as a DICOM series, for corrupting in the tests below.
fs::path small_series(const fs::path& dir) {
  Volume v;
  v.grid.size_vox = {24, 24, 10};
  v.grid.spacing_mm = {1.5, 1.5, 4.0};
  v.grid.origin_lps_mm = {-18, -18, -40};
  v.hu.assign(std::size_t(v.grid.voxel_count()), 40.0f);
  NullProgress np;
  DicomSeriesIds ids;
  ids.uid_seed = "cli-test";
  write_dicom_series(v, dir, ids, np);
  return dir;
}

void write_case(const fs::path& file, const std::string& input, const std::string& extra = "") {
  std::ofstream(file) << "[case]\nname = \"test\"\ninput = \"" << input << "\"\n" << extra;
}

}  // namespace

TEST(Cli, HelpExplainsEverySubcommand) {
  const auto r = run_cli("--help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* sub : {"info", "phantom", "run"}) EXPECT_NE(r.output.find(sub), std::string::npos) << sub;
  EXPECT_EQ(run_cli("frobnicate").exit_code, int(ExitCode::usage));
  EXPECT_EQ(run_cli("phantom").exit_code, int(ExitCode::usage));  // --out is required
}

TEST(Cli, EachBadInputHasItsOwnExitCodeAndWritesNothing) {
  ScratchDir tmp("cli-bad");
  // Build one directory per failure.
  fs::create_directories(tmp / "empty");
  fs::create_directories(tmp / "text");
  std::ofstream(tmp / "text" / "readme.txt") << "hello";
  {
    const fs::path d = small_series(tmp / "gap");
    std::vector<fs::path> f;
    for (const auto& e : fs::directory_iterator(d)) f.push_back(e.path());
    std::sort(f.begin(), f.end());
    fs::remove(f[4]);
  }
  {
    const fs::path d = small_series(tmp / "truncated");
    std::vector<fs::path> f;
    for (const auto& e : fs::directory_iterator(d)) f.push_back(e.path());
    std::sort(f.begin(), f.end());
    fs::resize_file(f[3], fs::file_size(f[3]) - 100);
  }
  small_series(tmp / "fine");

  struct Case {
    std::string name;
    fs::path input;
    std::string flags;
    ExitCode expected;
  };
  const std::vector<Case> cases = {
      {"empty", tmp / "empty", "", ExitCode::no_dicom},
      {"text", tmp / "text", "", ExitCode::no_dicom},
      {"gap", tmp / "gap", "", ExitCode::missing_slice},
      {"truncated", tmp / "truncated", "", ExitCode::corrupt_file},
      {"unknown series", tmp / "fine", "--series 9.9.9", ExitCode::series_not_found},
      {"missing path", tmp / "nowhere", "", ExitCode::input_not_found},
  };
  for (const auto& c : cases) {
    const auto info = run_cli("info " + quoted(c.input) + " " + c.flags);
    EXPECT_EQ(info.exit_code, int(c.expected)) << c.name << ": " << info.output;
    if (c.expected == ExitCode::ok) continue;
    // The message names the input and says what to do.
    EXPECT_NE(info.output.find("[error]"), std::string::npos) << c.name;
    EXPECT_NE(info.output.find("—"), std::string::npos) << c.name << " gives no advice: " << info.output;

    // The same input through `run`: same code, and no output directory at all.
    const fs::path case_file = tmp / ("case-" + std::to_string(&c - cases.data()) + ".toml");
    write_case(case_file, c.input.string());
    const fs::path out = tmp / ("out-" + std::to_string(&c - cases.data()));
    const auto run = run_cli("run " + quoted(case_file) + " --out " + quoted(out) + " " + c.flags);
    EXPECT_EQ(run.exit_code, int(c.expected)) << c.name << ": " << run.output;
    EXPECT_FALSE(fs::exists(out)) << c.name << ": a failed run left " << out;
  }
}

TEST(Cli, MemoryBudgetIsEnforcedFromTheCommandLine) {
  ScratchDir tmp("cli-mem");
  // 256 × 256 × 10 float voxels = 2.5 MiB > 1 MiB.
  Volume v;
  v.grid.size_vox = {256, 256, 10};
  v.hu.assign(std::size_t(v.grid.voxel_count()), 0.0f);
  NullProgress np;
  DicomSeriesIds ids;
  ids.uid_seed = "mem";
  write_dicom_series(v, tmp / "big", ids, np);
  EXPECT_EQ(run_cli("info " + quoted(tmp / "big") + " --max-memory-mb 1").exit_code, int(ExitCode::too_large));
  EXPECT_EQ(run_cli("info " + quoted(tmp / "big") + " --max-memory-mb 64").exit_code, 0);
}

TEST(Cli, NoPatientIdentifierReachesOutputsOrLogs) {
  ORGANSMITH_REQUIRE_REAL_DATA();
  const fs::path series = organsmith::testing::real_data_dir() / "chest-dicom-8mm" / "dicom";
  const std::string phi = "Lung_Dx-A0002";
  ScratchDir tmp("cli-phi");
  const auto info = run_cli("info " + quoted(series));
  ASSERT_EQ(info.exit_code, 0) << info.output;
  EXPECT_EQ(info.output.find(phi), std::string::npos);
  const auto info_json = run_cli("info --json " + quoted(series));
  EXPECT_EQ(info_json.output.find(phi), std::string::npos);

  write_case(tmp / "chest.toml", series.string(), "[[organ]]\nname = \"trachea\"\n");
  const auto run = run_cli("-v run " + quoted(tmp / "chest.toml") + " --until ingest --out " + quoted(tmp / "out"));
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(run.output.find(phi), std::string::npos);
  ASSERT_GT(organsmith::testing::count_files(tmp / "out"), 1u);
  EXPECT_FALSE(organsmith::testing::any_file_contains(tmp / "out", phi));
  // Every stage, whatever the segmentation's outcome, keeps identifiers out too.
  const auto full = run_cli("-v run " + quoted(tmp / "chest.toml") + " --out " + quoted(tmp / "full"));
  EXPECT_EQ(full.output.find(phi), std::string::npos);
  if (fs::exists(tmp / "full")) EXPECT_FALSE(organsmith::testing::any_file_contains(tmp / "full", phi));
  // …and the check itself can see the name where it is: the source files hold it.
  EXPECT_TRUE(organsmith::testing::any_file_contains(series, phi));
}

TEST(Cli, PhantomIsDeterministicForASeedAndReadableAsCt) {
  ScratchDir tmp("cli-phantom");
  const std::string args = " --size 96 --slice-mm 5";
  ASSERT_EQ(run_cli("phantom --out " + quoted(tmp / "a") + " --seed 3" + args).exit_code, 0);
  ASSERT_EQ(run_cli("phantom --out " + quoted(tmp / "b") + " --seed 3" + args).exit_code, 0);
  ASSERT_EQ(run_cli("phantom --out " + quoted(tmp / "c") + " --seed 4" + args).exit_code, 0);
  const auto a = file_digests(tmp / "a"), b = file_digests(tmp / "b"), c = file_digests(tmp / "c");
  ASSERT_TRUE(a.count("ground_truth.nii.gz"));
  ASSERT_TRUE(a.count("seeds.json"));
  EXPECT_EQ(a.size(), 3u + 80u);  // manifest, truth, seeds; 400 mm at 5 mm = 80 slices
  EXPECT_EQ(a, b);
  EXPECT_NE(a.at("dicom/IM0040.dcm"), c.at("dicom/IM0040.dcm"));

  // Our own reader and `info` accept it as CT with the requested geometry.
  const auto info = run_cli("info --json " + quoted(tmp / "a" / "dicom"));
  ASSERT_EQ(info.exit_code, 0) << info.output;
  const auto j = nlohmann::json::parse(info.output.substr(info.output.find('{')));
  EXPECT_EQ(j["series"]["modality"], "CT");
  EXPECT_EQ(j["size_vox"], nlohmann::json({96, 96, 80}));
  EXPECT_NEAR(j["spacing_mm"][2].get<double>(), 5.0, 1e-6);

  // An independent DICOM toolkit (DCMTK) parses it as CT Image Storage when installed.
  if (std::system("command -v dcmdump > /dev/null 2>&1") == 0) {
    const std::string cmd = "dcmdump " + quoted(tmp / "a" / "dicom" / "IM0001.dcm") + " 2>&1";
    FILE* p = popen(cmd.c_str(), "r");
    std::string dump;
    char buf[4096];
    std::size_t n;
    while ((n = fread(buf, 1, sizeof buf, p)) > 0) dump.append(buf, n);
    EXPECT_EQ(pclose(p), 0) << dump;
    EXPECT_NE(dump.find("=CTImageStorage"), std::string::npos) << dump.substr(0, 2000);
    EXPECT_NE(dump.find("(0028,1053) DS [1]"), std::string::npos) << "rescale slope missing";
  }
}

TEST(Cli, RunWritesManifestAndReusesUnchangedStages) {
  ScratchDir tmp("cli-run");
  write_case(tmp / "case.toml", "phantom",
             "[phantom]\nsize = 64\nslice_mm = 10\n[[organ]]\nname = \"gallbladder\"\n[[organ]]\nname = \"trachea\"\n");
  const fs::path out = tmp / "out";
  const auto first = run_cli("run " + quoted(tmp / "case.toml") + " --until ingest --out " + quoted(out));
  ASSERT_EQ(first.exit_code, 0) << first.output;
  const auto m1 = read_json(out / "manifest.json");
  EXPECT_EQ(m1["tool"]["name"], "organsmith");
  EXPECT_FALSE(m1["tool"]["git_commit"].get<std::string>().empty());
  EXPECT_EQ(m1["input"]["digest_sha256"].get<std::string>().size(), 64u);
  EXPECT_EQ(m1["case"]["phantom"]["size_vox"], 64);
  ASSERT_EQ(m1["stages"].size(), 2u);  // --until ingest: the segment stage has its own tests
  EXPECT_EQ(m1["stages"][0]["name"], "phantom");
  EXPECT_EQ(m1["stages"][1]["name"], "ingest");
  for (const auto& st : m1["stages"]) {
    EXPECT_EQ(st["status"], "ran");
    EXPECT_GT(st["peak_rss_mib"].get<double>(), 0.0);
    for (const auto& o : st["outputs"])
      EXPECT_EQ(sha256_file(out / o["path"].get<std::string>()), o["sha256"]) << o["path"];
  }
  // Seeds resolved from the phantom's seeds.json for the gallbladder; the trachea is automatic.
  const auto ingest = read_json(out / "ingest.json");
  EXPECT_EQ(ingest["organs"][0]["seed_source"], "phantom seeds.json");
  EXPECT_EQ(ingest["organs"][1]["seed_source"], "phantom seeds.json");
  // Each resolved seed index lands on its organ in the phantom's ground truth.
  const LabelMap truth = read_label_map(out / "phantom" / "ground_truth.nii.gz");
  for (const auto& [n, label] : {std::pair<int, int>{0, 1}, {1, 2}}) {
    const auto& ijk = ingest["organs"][n]["seed_ijk"];
    EXPECT_EQ(int(truth.at(std::lround(ijk[0].get<double>()), std::lround(ijk[1].get<double>()),
                           std::lround(ijk[2].get<double>()))),
              label)
        << ingest["organs"][n]["name"];
  }

  // Second run: nothing changed → every stage reused, outputs untouched.
  const auto before = file_digests(out / "phantom");
  const auto second = run_cli("run " + quoted(tmp / "case.toml") + " --until ingest --out " + quoted(out));
  ASSERT_EQ(second.exit_code, 0) << second.output;
  const nlohmann::json m2 = read_json(out / "manifest.json");  // a range-for over a member of a temporary dangles
  for (const auto& st : m2["stages"]) EXPECT_EQ(st["status"], "skipped (unchanged)");
  EXPECT_EQ(file_digests(out / "phantom"), before);

  // A changed option reruns; --force reruns everything.
  write_case(tmp / "case.toml", "phantom", "[phantom]\nsize = 64\nslice_mm = 10\nseed = 2\n");
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --until ingest --out " + quoted(out)).exit_code, 0);
  EXPECT_EQ(read_json(out / "manifest.json")["stages"][0]["status"], "ran");
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --until ingest --out " + quoted(out) + " --force").exit_code, 0);
  const nlohmann::json m4 = read_json(out / "manifest.json");
  for (const auto& st : m4["stages"]) EXPECT_EQ(st["status"], "ran");
  // No staging leftovers.
  for (const auto& e : fs::directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find("staging"), std::string::npos) << e.path();
}

TEST(Cli, BadCaseFileIsReportedWithItsLine) {
  ScratchDir tmp("cli-case");
  std::ofstream(tmp / "bad.toml") << "[case]\ninput = \"phantom\"\n\n[phantom]\nsizee = 64\n";
  const auto r = run_cli("run " + quoted(tmp / "bad.toml") + " --out " + quoted(tmp / "out"));
  EXPECT_EQ(r.exit_code, int(ExitCode::case_file));
  EXPECT_NE(r.output.find("sizee"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("line 5"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(tmp / "out"));
}
