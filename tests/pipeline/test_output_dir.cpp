// Output directories are safe: organsmith never deletes or replaces a file it did not write, never
// writes into or above its own input, refuses a user's non-empty folder or a file as --out, and
// leaves no staging folder behind on failure or after a kill.

#include "core/errors.h"
#include "core/sha256.h"
#include "pipeline/output/output_dir.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

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


void write_text(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}



/// A stage writer that puts `files` (relative path → text) into the staging folder.
std::function<void(const fs::path&)> writes(std::map<std::string, std::string> files) {
  return [files](const fs::path& staging) {
    for (const auto& [rel, text] : files) write_text(staging / rel, text);
  };
}


/// The user's folder every refusal below must leave byte for byte as it was.
fs::path users_folder(const ScratchDir& tmp) {
  const fs::path dir = tmp / "mine";
  write_text(dir / "notes.txt", "my notes\n");
  write_text(dir / "scan" / "IM0001.dcm", "not really DICOM, but mine\n");
  return dir;
}

}  // namespace

TEST(OutputDir, CommitsStagesListsTheirFilesAndReplacesOnlyThose) {
  ScratchDir tmp("outdir-commit");
  const fs::path out = tmp / "out";
  {
    OutputDir dir(out, OutputDirOptions{.command = "test"});
    EXPECT_FALSE(fs::exists(out)) << "nothing is created before the first commit";
    dir.commit("a", writes({{"a.txt", "1"}, {"sub/a2.txt", "2"}}));
    dir.commit("b", writes({{"b.txt", "3"}}));
  }
  auto m = read_json(out / "manifest.json");
  EXPECT_EQ(m["tool"]["name"], "organsmith");
  ASSERT_EQ(m["stages"].size(), 2u);
  EXPECT_EQ(m["stages"][0]["outputs"].size(), 2u);
  for (const auto& st : m["stages"])
    for (const auto& o : st["outputs"]) EXPECT_EQ(sha256_file(out / o["path"].get<std::string>()), o["sha256"]);

  // The user adds a file; a rerun of stage a with fewer outputs removes a's stale file, keeps
  // b's files and the user's, and replaces a.txt.
  write_text(out / "notes.txt", "mine");
  write_text(out / "sub" / "mine.txt", "mine too");
  {
    OutputDir dir(out, OutputDirOptions{.command = "test"});
    dir.commit("a", writes({{"a.txt", "new"}}));
  }
  EXPECT_EQ(organsmith::testing::read_file(out / "a.txt"), "new");
  EXPECT_FALSE(fs::exists(out / "sub" / "a2.txt"));
  EXPECT_EQ(organsmith::testing::read_file(out / "sub" / "mine.txt"), "mine too");
  EXPECT_EQ(organsmith::testing::read_file(out / "notes.txt"), "mine");
  EXPECT_EQ(organsmith::testing::read_file(out / "b.txt"), "3");
  m = read_json(out / "manifest.json");
  ASSERT_EQ(m["stages"].size(), 2u) << "stage b is kept from the earlier run";
  EXPECT_FALSE(has_staging_leftover(out));
}

TEST(OutputDir, NeverReplacesAFileItDidNotWrite) {
  ScratchDir tmp("outdir-foreign");
  const fs::path out = tmp / "out";
  OutputDir(out, OutputDirOptions{}).commit("a", writes({{"a.txt", "1"}}));
  write_text(out / "report.txt", "the user's report");
  write_text(out / "sub", "a file where an output folder would go");
  OutputDir dir(out, OutputDirOptions{});
  try {
    dir.commit("b", writes({{"report.txt", "organsmith's"}}));
    ADD_FAILURE() << "an output replaced the user's file";
  } catch (const OutputError& e) {
    EXPECT_EQ(e.path(), out / "report.txt");
  }
  EXPECT_THROW(dir.commit("b", writes({{"sub/x.txt", "x"}})), OutputError);
  EXPECT_EQ(organsmith::testing::read_file(out / "report.txt"), "the user's report");
  EXPECT_EQ(organsmith::testing::read_file(out / "sub"), "a file where an output folder would go");
  EXPECT_EQ(organsmith::testing::read_file(out / "a.txt"), "1");
  EXPECT_FALSE(has_staging_leftover(out));
}

TEST(OutputDir, AFailingStageLeavesNothingAndNoEmptyFolder) {
  ScratchDir tmp("outdir-fail");
  const fs::path out = tmp / "new";
  OutputDir dir(out, OutputDirOptions{});
  EXPECT_THROW(dir.commit("a",
                          [](const fs::path& staging) {
                            write_text(staging / "half.txt", "half");
                            throw OutputError("disk full", staging / "half.txt");
                          }),
               OutputError);
  EXPECT_FALSE(fs::exists(out)) << "a run that wrote nothing leaves no output directory";
}

TEST(OutputDir, AKilledCommitIsListedAndTheRerunReplacesItsFiles) {
  ScratchDir tmp("outdir-kill");
  const fs::path out = tmp / "out";
  OutputDir(out, OutputDirOptions{}).commit("a", writes({{"a.txt", "1"}}));
  // What a kill between the manifest's pending record and the end of the move leaves: the
  // manifest lists old and new files under an interrupted record; a staging folder remains.
  auto m = read_json(out / "manifest.json");
  m["stages"][0]["status"] = "interrupted";
  m["stages"][0]["fingerprint"] = "";
  m["stages"][0]["outputs"].push_back({{"path", "c.txt"}, {"bytes", 1}, {"sha256", sha256_hex("c")}});
  write_text(out / "manifest.json", m.dump(2));
  write_text(out / "c.txt", "c");
  write_text(out / ".a.staging-1f2e3d" / "c.txt", "c");
  write_text(out / ".manifest.json.tmp4242", "{");

  OutputDir dir(out, OutputDirOptions{});
  EXPECT_FALSE(fs::exists(out / ".a.staging-1f2e3d")) << "leftovers of a killed run are removed on open";
  EXPECT_FALSE(fs::exists(out / ".manifest.json.tmp4242"));
  ASSERT_NE(dir.stage_record("a"), nullptr);
  EXPECT_EQ((*dir.stage_record("a"))["fingerprint"], "");
  dir.commit("a", writes({{"a.txt", "2"}}));
  EXPECT_FALSE(fs::exists(out / "c.txt")) << "the interrupted stage's files belong to organsmith";
  EXPECT_EQ(organsmith::testing::read_file(out / "a.txt"), "2");
}

TEST(OutputDir, RefusesUsersFoldersFilesAndItsOwnInput) {
  ScratchDir tmp("outdir-refuse");
  const fs::path mine = users_folder(tmp);
  const auto before = file_digests(mine);
  auto refuses = [&](const fs::path& out, std::vector<fs::path> inputs) {
    try {
      OutputDir(out, OutputDirOptions{.inputs = std::move(inputs), .command = "test"});
      return false;
    } catch (const OutputError& e) {
      EXPECT_FALSE(e.hint().empty()) << "says how to proceed";
      return true;
    }
  };
  EXPECT_TRUE(refuses(mine, {}));                                  // non-empty, no manifest
  EXPECT_TRUE(refuses(mine / "notes.txt", {}));                    // a file
  EXPECT_TRUE(refuses(mine / "scan", {mine / "scan"}));            // its own input
  EXPECT_TRUE(refuses(mine / "scan" / "sub", {mine / "scan"}));    // inside the input
  EXPECT_FALSE(refuses(tmp / "elsewhere", {mine / "scan"}));
  EXPECT_EQ(file_digests(mine), before);
  // An empty folder is fine; a folder organsmith wrote accepts its own file as input.
  fs::create_directories(tmp / "empty");
  EXPECT_FALSE(refuses(tmp / "empty", {}));
  OutputDir(tmp / "seg", OutputDirOptions{}).commit("segment", writes({{"labels.nii.gz", "l"}}));
  EXPECT_FALSE(refuses(tmp / "seg", {tmp / "seg" / "labels.nii.gz"}));
  write_text(tmp / "seg" / "user.nii.gz", "u");
  EXPECT_TRUE(refuses(tmp / "seg", {tmp / "seg" / "user.nii.gz"}));
}

// The five data-destroying command lines of the reliability report, as a user types them.
TEST(OutputDirCli, CommandsNeverDeleteTheUsersFiles) {
  ScratchDir tmp("outdir-cli");
  const fs::path mine = users_folder(tmp);
  write_text(mine / "labels.nii.gz", "a label map of the user's");
  const auto before = file_digests(mine);
  std::string log;
  auto expect_refused = [&](const std::string& args) {
    const int rc = run_cli(args, &log);
    EXPECT_EQ(rc, int(ExitCode::output)) << args << "\n" << log;
    EXPECT_NE(log.find(mine.string()), std::string::npos) << "names the directory: " << log;
    EXPECT_EQ(file_digests(mine), before) << args;
  };
  expect_refused("segment " + quoted(mine / "scan") + " --out " + quoted(mine / "scan") + " --organ trachea");
  expect_refused("segment " + quoted(mine / "scan") + " --out " + quoted(mine) + " --organ trachea");
  expect_refused("mesh " + quoted(mine / "labels.nii.gz") + " --out " + quoted(mine));
  expect_refused("phantom --out " + quoted(mine) + " --size 64 --slice-mm 10");
  expect_refused("phantom --out " + quoted(mine / "notes.txt") + " --size 64 --slice-mm 10");
  expect_refused("degrade --out " + quoted(mine) + " --weeks 1");
  expect_refused("calibrate --model ogden --data " + quoted(mine / "notes.txt") + " --out " + quoted(mine));
  // `--out .` inside the user's folder.
  const std::string in_mine = "cd " + quoted(mine) + " && " + std::string(ORGANSMITH_CLI) + " phantom --out . --size 64";
  EXPECT_EQ(WEXITSTATUS(std::system((in_mine + " > /dev/null 2>&1").c_str())), int(ExitCode::output));
  EXPECT_EQ(file_digests(mine), before);

  // An output below a file, or where nothing can be written.
  EXPECT_EQ(run_cli("phantom --out " + quoted(mine / "notes.txt" / "sub") + " --size 64 --slice-mm 10", &log),
            int(ExitCode::output))
      << log;
  EXPECT_EQ(run_cli("phantom --out /proc/organsmith --size 64 --slice-mm 10", &log), int(ExitCode::output)) << log;
  EXPECT_EQ(file_digests(mine), before);
}

TEST(OutputDirCli, ARerunReplacesItsOwnOutputsAndKeepsTheUsersFiles) {
  ScratchDir tmp("outdir-rerun");
  const fs::path out = tmp / "ph";
  std::string log;
  ASSERT_EQ(run_cli("phantom --out " + quoted(out) + " --size 64 --slice-mm 10 --seed 1", &log), 0) << log;
  write_text(out / "notes.txt", "mine");
  write_text(out / "dicom" / "README", "mine too");
  ASSERT_EQ(run_cli("phantom --out " + quoted(out) + " --size 64 --slice-mm 20 --seed 2", &log), 0) << log;
  EXPECT_EQ(organsmith::testing::read_file(out / "notes.txt"), "mine");
  EXPECT_EQ(organsmith::testing::read_file(out / "dicom" / "README"), "mine too");
  // 400 mm at 20 mm: 20 slices; the 40 of the first run are gone.
  std::size_t slices = 0;
  for (const auto& e : fs::directory_iterator(out / "dicom")) slices += e.path().extension() == ".dcm";
  EXPECT_EQ(slices, 20u);
  const auto m = read_json(out / "manifest.json");
  ASSERT_EQ(m["stages"].size(), 1u);
  for (const auto& o : m["stages"][0]["outputs"])
    EXPECT_EQ(sha256_file(out / o["path"].get<std::string>()), o["sha256"]) << o["path"];
  EXPECT_FALSE(has_staging_leftover(out));
}
