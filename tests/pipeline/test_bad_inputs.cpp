// Bad case files, out-of-range options and signals: each ends with its documented exit code, in
// seconds, naming what is wrong, and leaves nothing half-written (reliability).

#include "core/errors.h"
#include "core/process.h"
#include "core/sha256.h"
#include "pipeline/io/image_io.h"
#include "tests/support/test_support.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <thread>

using namespace organsmith;
using organsmith::testing::run_cli;
using organsmith::testing::ScratchDir;
using organsmith::testing::file_digests;
using organsmith::testing::has_staging_leftover;
using organsmith::testing::quoted;
using organsmith::testing::read_json;
namespace fs = std::filesystem;

namespace {



/// Starts the CLI with `args` (no shell), output to `log`; returns its pid.
pid_t spawn_cli(const std::vector<std::string>& args, const fs::path& log) {
  const pid_t pid = fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1), dup2(fd, 2);
    std::vector<char*> argv{const_cast<char*>(ORGANSMITH_CLI)};
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(ORGANSMITH_CLI, argv.data());
    _exit(127);
  }
  return pid;
}

/// Waits for `pid` up to `timeout`; returns its exit status (or -1 on timeout, after killing it).
int wait_exit(pid_t pid, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (std::chrono::steady_clock::now() < deadline) {
    if (waitpid(pid, &status, WNOHANG) == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(pid, SIGKILL);
  waitpid(pid, &status, 0);
  return -1;
}

/// Polls until process `pid` catches SIGINT (its handler is installed first thing in main; the
/// shared libraries' constructors before main take ≈ 0.2 s, in which the default action applies).
bool wait_for_sigint_handler(pid_t pid, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    std::ifstream status("/proc/" + std::to_string(pid) + "/status");
    std::string line;
    while (std::getline(status, line))
      if (line.rfind("SigCgt:", 0) == 0 && (std::stoull(line.substr(7), nullptr, 16) & (1ull << (SIGINT - 1))))
        return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

/// Polls until `file` exists (or the deadline passes).
bool wait_for_file(const fs::path& file, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (fs::exists(file)) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

}  // namespace

TEST(BadInputs, CaseFileMistakesHaveTheirCodesAndNameTheFile) {
  ScratchDir tmp("bad-case");
  std::string log;
  auto code = [&](const std::string& name, const std::string& text) {
    std::ofstream(tmp / name, std::ios::binary) << text;
    const fs::path out = tmp / ("out-" + name);
    const int rc = run_cli("run " + quoted(tmp / name) + " --out " + quoted(out), &log);
    EXPECT_NE(log.find(name), std::string::npos) << "names the file: " << log;
    // Only a case without organs gets as far as reading its input (a bad input is said first).
    if (name != "noorgan.toml") EXPECT_FALSE(fs::exists(out)) << name;
    return rc;
  };
  EXPECT_EQ(code("empty.toml", ""), int(ExitCode::case_file)) << log;
  EXPECT_EQ(code("noinput.toml", "[case]\nname = \"x\"\n[[organ]]\nname = \"trachea\"\n"), int(ExitCode::case_file)) << log;
  EXPECT_EQ(code("noorgan.toml", "[case]\ninput = \"phantom\"\n[phantom]\nsize = 64\n"), int(ExitCode::case_file)) << log;
  EXPECT_EQ(code("latin1.toml", "[case]\ninput = \"phantom\"\nname = \"caf\xe9\"\n"), int(ExitCode::case_file)) << log;
  EXPECT_NE(log.find("line 3"), std::string::npos) << log;
  EXPECT_EQ(code("nanpreset.toml", "[case]\ninput = \"phantom\"\n[[organ]]\nname = \"trachea\"\n"
                                   "[stages.segment.presets.trachea]\nalpha = nan\n"),
            int(ExitCode::case_file))
      << log;
  EXPECT_EQ(run_cli("run " + quoted(tmp / "absent.toml"), &log), int(ExitCode::input_not_found)) << log;
  EXPECT_NE(log.find("absent.toml"), std::string::npos) << log;
}

TEST(BadInputs, MeshOptionsOutOfReachOfTheDataStopAtOnce) {
  ScratchDir tmp("bad-mesh");
  LabelMap lm;
  lm.grid.size_vox = {40, 40, 20};
  lm.grid.spacing_mm = {1.0, 1.0, 2.0};
  lm.labels.assign(std::size_t(lm.grid.voxel_count()), 0);
  for (std::int64_t k = 5; k < 15; ++k)  // a 20 × 20 × 20 mm block of gallbladder
    for (std::int64_t j = 10; j < 30; ++j)
      for (std::int64_t i = 10; i < 30; ++i) lm.labels[lm.grid.offset(i, j, k)] = 1;
  write_label_map(lm, tmp / "block.nii.gz");
  std::string log;
  for (const std::string flags : {"--edge-mm 1e9", "--edge-mm 0.001", "--wall-mm gallbladder=1000"}) {
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_EQ(run_cli("mesh " + quoted(tmp / "block.nii.gz") + " --organ gallbladder " + flags + " --out " + quoted(tmp / "out"),
                      &log),
              int(ExitCode::mesh_input))
        << flags << "\n" << log;
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(30)) << flags;
    EXPECT_NE(log.find("gallbladder"), std::string::npos) << log;
    EXPECT_FALSE(fs::exists(tmp / "out")) << flags;
  }
  EXPECT_EQ(run_cli("degrade --out " + quoted(tmp / "d") + " --dt-days 1e-12", &log), int(ExitCode::usage)) << log;
  EXPECT_FALSE(fs::exists(tmp / "d"));
}

// Ctrl-C at any moment exits 40 with nothing half-written; a SIGKILL mid-run leaves a directory
// that the rerun completes, with every file matching its manifest hash and no staging folder.
TEST(BadInputs, InterruptAndKillMidRunThenRerun) {
  ScratchDir tmp("signals");
  std::ofstream(tmp / "case.toml") << "[case]\nname = \"sig\"\ninput = \"phantom\"\n[phantom]\nsize = 256\n"
                                      "[[organ]]\nname = \"gallbladder\"\n[[organ]]\nname = \"trachea\"\n"
                                      "[stages.snapshot]\nviews = [\"organs\"]\nwidth_px = 320\nheight_px = 240\n";
  const std::vector<std::string> run = {"run", (tmp / "case.toml").string(), "--out", (tmp / "out").string()};
  // SIGINT at once (before any stage) and once the mesh stage is under way.
  for (const char* when : {"start", "mesh"}) {
    SCOPED_TRACE(when);
    const pid_t pid = spawn_cli(run, tmp / "log.txt");
    if (std::string(when) == "mesh")
      ASSERT_TRUE(wait_for_file(tmp / "out" / "labels.nii.gz", std::chrono::seconds(120)));
    else
      ASSERT_TRUE(wait_for_sigint_handler(pid, std::chrono::seconds(30)));
    kill(pid, SIGINT);
    const int rc = wait_exit(pid, std::chrono::seconds(120));
    EXPECT_EQ(rc, int(ExitCode::cancelled)) << organsmith::testing::read_file(tmp / "log.txt");
    if (fs::exists(tmp / "out")) EXPECT_FALSE(has_staging_leftover(tmp / "out"));
  }
  // SIGKILL while meshing, then the rerun.
  const pid_t pid = spawn_cli({"run", (tmp / "case.toml").string(), "--out", (tmp / "out").string(), "--force"},
                              tmp / "log.txt");
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  kill(pid, SIGKILL);
  wait_exit(pid, std::chrono::seconds(30));
  std::string log;
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(tmp / "out"), &log), 0) << log;
  EXPECT_FALSE(has_staging_leftover(tmp / "out"));
  std::ifstream in(tmp / "out" / "manifest.json");
  const nlohmann::json m = nlohmann::json::parse(in);
  std::size_t files = 0;
  for (const auto& st : m["stages"]) {
    EXPECT_NE(st["status"], "interrupted") << st["name"];
    for (const auto& o : st["outputs"]) {
      ++files;
      EXPECT_EQ(sha256_file(tmp / "out" / o["path"].get<std::string>()), o["sha256"]) << o["path"];
    }
  }
  EXPECT_GT(files, 30u);
  EXPECT_TRUE(fs::exists(tmp / "out" / "snapshots" / "3d_trachea.png"));
}

// A device or a named pipe given as the scan is refused at once (reading it would never end, and it
// is no empty directory), naming it.
TEST(BadInputs, ADeviceOrAPipeIsNoScan) {
  ScratchDir tmp("bad-kind");
  const fs::path fifo = tmp / "scan.pipe";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  for (const fs::path& input : {fs::path("/dev/zero"), fifo}) {
    std::string out;
    EXPECT_EQ(run_cli("info " + quoted(input), &out), int(ExitCode::unsupported_input)) << out;
    EXPECT_NE(out.find("neither a file nor a directory"), std::string::npos) << out;
    EXPECT_NE(out.find(input.string()), std::string::npos) << out;
  }
}

// A disk that fills up while DICOM slices are written (`phantom`, and `run` of the phantom case):
// exit 30 naming the folder, no abort from the DICOM library, nothing half-written left behind;
// the same command on a disk with room then completes.
TEST(BadInputs, AFullDiskWhileWritingDicomIsExit30AndLeavesNothing) {
  organsmith::testing::SmallDisk disk("fulldisk", 1024);
  if (!disk.mounted()) GTEST_SKIP() << disk.why();
  ScratchDir tmp("fulldisk-case");
  std::ofstream(tmp / "case.toml") << "[case]\nname = \"full\"\ninput = \"phantom\"\n[phantom]\nsize = 128\n"
                                      "[[organ]]\nname = \"gallbladder\"\n";
  const std::vector<std::pair<std::string, std::string>> commands = {
      {"phantom", "phantom --out " + quoted(disk / "ph") + " --size 128"},
      {"run", "run " + quoted(tmp / "case.toml") + " --out " + quoted(disk / "run")}};
  for (const auto& [name, args] : commands) {
    SCOPED_TRACE(name);
    const auto r = run_cli(args);
    EXPECT_EQ(r.exit_code, int(ExitCode::output)) << r.output;
    EXPECT_NE(r.output.find(disk.path().string()), std::string::npos) << r.output;
    const fs::path out = disk / (name == "phantom" ? "ph" : "run");
    std::size_t dicom_left = 0;
    if (fs::exists(out)) {
      EXPECT_FALSE(has_staging_leftover(out));
      for (const auto& e : fs::recursive_directory_iterator(out)) dicom_left += e.path().extension() == ".dcm";
    }
    EXPECT_EQ(dicom_left, 0u) << "DICOM slices left behind in " << out;
  }
  // With room, the same phantom completes.
  const auto ok = run_cli("phantom --out " + quoted(tmp / "ph") + " --size 128");
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
}

// The solver's bad days: CalculiX killed from outside mid-step, a disk that fills while it writes,
// and a corrupt INP (an unstable law; a step the solver cannot finish). Each ends in its documented
// code (71 naming the signal or the kept solver log; 30 naming the folder; 18 naming the INP) with
// no results and no staging folder left; with the solver left alone, room on the disk and the INP
// restored, the rerun completes.
TEST(BadInputs, SolverKilledOrDiskFullDuringSimulateThenRerun) {
  if (organsmith::find_on_path("ccx").empty()) GTEST_SKIP() << "CalculiX (ccx) not installed: apt-get install calculix-ccx";
  organsmith::testing::SmallDisk disk("simfault", 96 * 1024);
  if (!disk.mounted()) GTEST_SKIP() << disk.why();
  ScratchDir tmp("simfault-case");
  std::ofstream(tmp / "case.toml") << "[case]\ninput = \"phantom\"\n[phantom]\nsize = 256\n[[organ]]\nname = \"gallbladder\"\n"
                                      "[stages.mesh]\nedge_mm = 3.0\ntet_edge_mm = 6.0\nformats = [\"inp\"]\n";
  const fs::path out = disk / "out";
  std::string log;
  ASSERT_EQ(run_cli("run " + quoted(tmp / "case.toml") + " --out " + quoted(out) + " --until mesh", &log), 0) << log;

  // SIGKILL to the solver once it has converged an increment or two.
  const pid_t pid = spawn_cli({"simulate", out.string(), "--organ", "gallbladder"}, tmp / "sim.log");
  bool stepping = false;
  for (const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
       !stepping && std::chrono::steady_clock::now() < until;) {
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(out, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
      if (it->path().filename() == "job.sta" && fs::file_size(it->path(), ec) > 250) stepping = true;
    if (!stepping) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_TRUE(stepping) << organsmith::testing::read_file(tmp / "sim.log");
  ASSERT_EQ(std::system(("pkill -KILL -P " + std::to_string(pid)).c_str()), 0);
  EXPECT_EQ(wait_exit(pid, std::chrono::seconds(60)), int(ExitCode::solver_failed)) << organsmith::testing::read_file(tmp / "sim.log");
  const std::string killed = organsmith::testing::read_file(tmp / "sim.log");
  EXPECT_NE(killed.find("signal 9"), std::string::npos) << killed;
  EXPECT_NE(killed.find("run simulate again"), std::string::npos) << killed;
  EXPECT_FALSE(fs::exists(out / "simulation"));
  EXPECT_FALSE(has_staging_leftover(out));

  // The disk full but for 1.5 MiB: the solver's results do not fit.
  {
    const std::uintmax_t keep = 3u << 19, available = fs::space(disk.path()).available;
    ASSERT_GT(available, keep);
    std::ofstream filler(disk / "filler", std::ios::binary);
    const std::string chunk(1u << 16, 'x');
    for (std::uintmax_t left = available - keep; left >= chunk.size(); left -= chunk.size()) filler.write(chunk.data(), std::streamsize(chunk.size()));
  }
  const auto full = run_cli("simulate " + quoted(out) + " --organ gallbladder");
  EXPECT_EQ(full.exit_code, int(ExitCode::output)) << full.output;
  EXPECT_NE(full.output.find(out.string()), std::string::npos) << full.output;
  EXPECT_FALSE(fs::exists(out / "simulation"));
  EXPECT_FALSE(has_staging_leftover(out));

  fs::remove(disk / "filler");

  // A corrupt INP: a law with a sign flipped is refused before the solver (18, naming the INP and
  // the material); a step the solver cannot finish (its increment limit cut to 2) is 71, and the
  // message points at the solver's log, kept outside the removed staging folder.
  const fs::path inp = out / "meshes" / "gallbladder" / "gallbladder.inp";
  const std::string good = organsmith::testing::read_file(inp);
  const auto edit = [&](const std::string& from, const std::string& to) {
    std::string text = good;
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    std::ofstream(inp, std::ios::binary) << text;
  };
  {
    const auto at = good.find("*HYPERELASTIC, OGDEN");
    ASSERT_NE(at, std::string::npos);
    const auto line = good.find('\n', at) + 1;
    edit(good.substr(line, good.find('\n', line) - line), "-" + good.substr(line, good.find('\n', line) - line));
  }
  const auto unstable = run_cli("simulate " + quoted(out) + " --organ gallbladder");
  EXPECT_EQ(unstable.exit_code, int(ExitCode::unsupported_input)) << unstable.output;
  EXPECT_NE(unstable.output.find(inp.string()), std::string::npos) << unstable.output;
  EXPECT_NE(unstable.output.find("_MAT"), std::string::npos) << unstable.output;
  edit("*STEP, NLGEOM, INC=1000", "*STEP, NLGEOM, INC=2");
  const auto stalled = run_cli("simulate " + quoted(out) + " --organ gallbladder");
  EXPECT_EQ(stalled.exit_code, int(ExitCode::solver_failed)) << stalled.output;
  const fs::path kept = out / "logs" / "simulate_gallbladder_solver.log";
  EXPECT_NE(stalled.output.find(kept.string()), std::string::npos) << stalled.output;
  EXPECT_NE(organsmith::testing::read_file(kept).find("*ERROR"), std::string::npos) << "the kept log holds the solver's account";
  EXPECT_FALSE(fs::exists(out / "simulation"));
  EXPECT_FALSE(has_staging_leftover(out));

  std::ofstream(inp, std::ios::binary) << good;
  ASSERT_EQ(run_cli("simulate " + quoted(out) + " --organ gallbladder", &log), 0) << log;
  const nlohmann::json s = organsmith::testing::read_json(out / "simulation" / "gallbladder.json");
  EXPECT_TRUE(s["converged"].get<bool>()) << s.dump(2);
  EXPECT_FALSE(has_staging_leftover(out));
  EXPECT_FALSE(fs::exists(out / "logs")) << "a success removes the failed run's log";
}
