// Cohorts (`organsmith cohort`): validation of the cohort file, the local pool and a real Slurm
// cluster giving the same studies byte for byte, a broken study that stops nothing, reuse on a
// rerun, a study killed mid-run, the Slurm controller stopped mid-cohort, a disk that fills, and
// no input path in anything a cohort shows.
#include "tests/support/test_support.h"

#include "core/csv.h"

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <cstring>
#include <cstdlib>
#include <fstream>
#include <thread>

using namespace organsmith::testing;
namespace fs = std::filesystem;

namespace {

/// The folder the broken study's input lives in: a patient's name, which nothing the cohort shows
/// may repeat.
constexpr const char* kPatientFolder = "Doe_Jane_1957";

/// The shared case of every cohort here: a 64² phantom with 10 mm slices, the gallbladder only
/// (the engines are what these tests check; its trachea spends a minute in the mesh remedies).
constexpr const char* kSmallCase =
    "[case]\ninput = \"phantom\"\n[phantom]\nsize = 64\nslice_mm = 10\n[[organ]]\nname = \"gallbladder\"\n";

void write(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

/// Three small phantoms (seeds 1–3) and a study whose input is not DICOM.
void write_cohort(const fs::path& dir) {
  write(dir / "shared.toml", kSmallCase);
  write(dir / kPatientFolder / "IM0001.dcm", "this is not a DICOM file\n");
  write(dir / "cohort.csv",
        std::string("id,input,phantom.seed\ns1,phantom,1\ns2,phantom,2\nbroken,") + kPatientFolder + ",\ns3,phantom,3\n");
}

std::map<std::string, nlohmann::json> studies_by_id(const fs::path& out) {
  std::map<std::string, nlohmann::json> m;
  const nlohmann::json summary = read_json(out / "cohort.json");  // kept: the loop runs over its member
  for (const auto& s : summary.at("studies")) m[s.at("id").get<std::string>()] = s;
  return m;
}

/// The files a study's manifest lists, with their digests (what "byte for byte" compares).
std::map<std::string, std::string> manifest_digests(const fs::path& study) {
  std::map<std::string, std::string> m;
  const auto manifest = read_json(study / "manifest.json");
  for (const auto& stage : manifest.at("stages"))
    for (const auto& o : stage.at("outputs")) m[o.at("path").get<std::string>()] = o.at("sha256").get<std::string>();
  return m;
}

/// Every file the manifest lists is there with its recorded digest, and no staging folder is left.
void expect_complete(const fs::path& study) {
  const auto listed = manifest_digests(study);
  EXPECT_GT(listed.size(), 50u) << study;
  const auto actual = file_digests(study, "manifest.json");
  for (const auto& [path, digest] : listed) EXPECT_EQ(actual.count(path) ? actual.at(path) : "missing", digest) << path;
  EXPECT_FALSE(has_staging_leftover(study)) << study;
}

/// A private one-node Slurm cluster (tests/support/slurm_cluster.sh), stopped by PID when the
/// object dies, also when the test fails.
class SlurmCluster {
 public:
  SlurmCluster() {
    char dir[] = "/tmp/osm-slurm-XXXXXX";  // short: Slurm's socket paths live under it
    if (!mkdtemp(dir)) return;
    dir_ = dir;
    const std::string script = std::string(ORGANSMITH_SOURCE_DIR) + "/tests/support/slurm_cluster.sh";
    const std::string cmd = "'" + script + "' start '" + dir_.string() + "' > '" + dir_.string() + "/start.log' 2>&1";
    const int rc = std::system(cmd.c_str());
    start_log_ = read_file(dir_ / "start.log");
    if (WIFEXITED(rc) && WEXITSTATUS(rc) == 0) {
      setenv("SLURM_CONF", (dir_ / "slurm.conf").c_str(), 1);
      up_ = true;
    } else {
      missing_tools_ = WIFEXITED(rc) && WEXITSTATUS(rc) == 3;
    }
  }
  ~SlurmCluster() {
    if (dir_.empty()) return;
    (void)command("stop", "/dev/null");
    unsetenv("SLURM_CONF");
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  bool up() const { return up_; }
  bool missing_tools() const { return missing_tools_; }
  const std::string& start_log() const { return start_log_; }
  /// True while any daemon of this cluster runs.
  bool daemons_alive() const {
    for (const char* d : {"munged", "slurmctld", "slurmd"}) {
      std::ifstream f(dir_ / "run" / (std::string(d) + ".pid"));
      int pid = 0;
      if (f >> pid && pid > 0 && kill(pid, 0) == 0) return true;
    }
    return false;
  }
  fs::path dir() const { return dir_; }
  /// `slurm_cluster.sh WHAT DIR` (stop-controller, start-controller, stop), its output appended
  /// to `log`; the script's exit code.
  int command(const std::string& what, const fs::path& log) const {
    const std::string script = std::string(ORGANSMITH_SOURCE_DIR) + "/tests/support/slurm_cluster.sh";
    const int rc = std::system(("'" + script + "' " + what + " '" + dir_.string() + "' >> '" + log.string() + "' 2>&1").c_str());
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  }

 private:
  fs::path dir_;
  std::string start_log_;
  bool up_ = false, missing_tools_ = false;
};

/// PID of the process running study `index` of the cohort in `out` (`organsmith … cohort-study OUT INDEX`), or 0.
int study_process(const fs::path& out, int index) {
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string name = e.path().filename();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::string cmdline = read_file(e.path() / "cmdline");
    for (char& c : cmdline)
      if (c == '\0') c = ' ';
    if (cmdline.find("cohort-study " + out.string() + " " + std::to_string(index) + " ") != std::string::npos)
      return std::stoi(name);
  }
  return 0;
}

/// Waits until study `index` has committed at least one stage, then SIGKILLs its process.
bool kill_study_mid_run(const fs::path& out, const std::string& id, int index) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (std::chrono::steady_clock::now() < deadline) {
    const int pid = study_process(out, index);
    if (pid > 0 && fs::exists(out / id / "manifest.json") && fs::exists(out / id / "ingest.json")) {
      kill(pid, SIGKILL);
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

void expect_no_input_path(const fs::path& out) {
  for (const fs::path& p : {out / "cohort.csv", out / "cohort.json", out / "cohort" / "cohort.sbatch"})
    if (fs::exists(p)) EXPECT_EQ(read_file(p).find(kPatientFolder), std::string::npos) << p;
  for (const char* sub : {"logs", "status"})
    EXPECT_FALSE(any_file_contains(out / "cohort" / sub, kPatientFolder)) << sub;
}

}  // namespace

TEST(Cohort, ValidationListsEveryErrorOfEveryRowAtOnce) {
  ScratchDir tmp("cohort-validate");
  write(tmp / "shared.toml", "[case]\ninput = \"phantom\"\n[phantom]\nsize = 64\n[[organ]]\nname = \"gallbladder\"\n");
  write(tmp / "cohort.csv",
        "id,input,phantom.seed,seed_lps_mm.trachea,stages.mesh.bogus_key\n"
        "ok,phantom,1,,\n"
        "bad id!,phantom,1,,\n"           // line 3: not a folder name
        "ok,phantom,1,,\n"                // line 4: the id again
        "s4,no/such/folder,1,,\n"         // line 5: missing input
        "s5,phantom,many,,\n"             // line 6: phantom.seed is no integer
        "s6,phantom,1,1 2,\n"             // line 7: two numbers for a seed, organ not in the case
        "s7,phantom,1,,7\n");             // line 8: an unknown stage option
  const CliResult r = run_cli("cohort " + quoted(tmp / "cohort.csv") + " --case " + quoted(tmp / "shared.toml") +
                              " --out " + quoted(tmp / "out"));
  EXPECT_EQ(r.exit_code, 20) << r.output;
  for (const char* expected : {"line 3, column 1 (id)", "line 4, column 1 (id): the id 'ok' is used twice",
                               "line 5, column 2 (input): the input does not exist", "line 6 (study 's5')",
                               "line 7, column 4 (seed_lps_mm.trachea)", "line 8 (study 's7')", "bogus_key"})
    EXPECT_NE(r.output.find(expected), std::string::npos) << expected << "\n" << r.output;
  EXPECT_FALSE(fs::exists(tmp / "out")) << "nothing is written for an invalid cohort";

  write(tmp / "cols.csv", "id,input,colour\ns1,phantom,red\n");
  const CliResult c = run_cli("cohort " + quoted(tmp / "cols.csv") + " --out " + quoted(tmp / "out"));
  EXPECT_EQ(c.exit_code, 20);
  EXPECT_NE(c.output.find("'colour' is no cohort column"), std::string::npos) << c.output;
}

TEST(Cohort, LocalAndSlurmRunTheSameStudiesAndABrokenOneStopsNothing) {
  ScratchDir tmp("cohort-engines");
  write_cohort(tmp.path());
  const std::string args = "cohort " + quoted(tmp / "cohort.csv") + " --case " + quoted(tmp / "shared.toml") + " --poll-s 0.2";

  // Local pool.
  const fs::path local = tmp / "local";
  const CliResult r = run_cli(args + " --out " + quoted(local));
  ASSERT_EQ(r.exit_code, 80) << r.output;  // some studies failed: 80, and every other study completed
  auto studies = studies_by_id(local);
  for (const char* id : {"s1", "s2", "s3"}) {
    EXPECT_EQ(studies[id]["state"], "done") << id;
    expect_complete(local / id);
    EXPECT_GT(studies[id]["organs"]["gallbladder"]["label_volume_ml"].get<double>(), 5.0) << id;
    EXPECT_GT(studies[id]["peak_rss_mib"].get<double>(), 50.0) << id;
  }
  EXPECT_EQ(studies["broken"]["state"], "failed");
  EXPECT_EQ(studies["broken"]["exit_code"], 10);  // no DICOM image: the study's own exit code
  EXPECT_EQ(studies["broken"]["attempts"], 1);    // a bad input is not retried
  EXPECT_NE(studies["broken"]["message"].get<std::string>().find("<input>"), std::string::npos);
  const auto table = organsmith::parse_csv(read_file(local / "cohort.csv"), "cohort.csv", organsmith::ExitCode::case_file);
  EXPECT_EQ(table.rows.size(), 4u);
  EXPECT_GE(table.column("gallbladder_tet_min_dihedral_deg"), 0);
  EXPECT_EQ(read_file(local / "cohort.png").substr(1, 3), "PNG");
  expect_no_input_path(local);

  // A rerun reuses the completed studies (their files untouched) and tries the broken one again.
  const auto before = file_digests(local / "s2");
  const auto mtime = fs::last_write_time(local / "s2" / "labels.nii.gz");
  const CliResult again = run_cli(args + " --out " + quoted(local));
  EXPECT_EQ(again.exit_code, 80) << again.output;
  studies = studies_by_id(local);
  for (const char* id : {"s1", "s2", "s3"}) EXPECT_EQ(studies[id]["state"], "reused") << id;
  EXPECT_EQ(studies["broken"]["state"], "failed");
  EXPECT_EQ(file_digests(local / "s2"), before);
  EXPECT_EQ(fs::last_write_time(local / "s2" / "labels.nii.gz"), mtime);

  // The same cohort on a real one-node Slurm cluster.
  fs::path slurm_dir;
  {
    SlurmCluster cluster;
    if (cluster.missing_tools()) GTEST_SKIP() << "Slurm is not installed (scripts/install-deps installs slurm-wlm, munge)";
    ASSERT_TRUE(cluster.up()) << cluster.start_log();
    slurm_dir = cluster.dir();
    const fs::path on_slurm = tmp / "slurm";
    const CliResult s = run_cli(args + " --engine slurm --out " + quoted(on_slurm));
    ASSERT_EQ(s.exit_code, 80) << s.output;
    const auto by_slurm = studies_by_id(on_slurm);
    for (const char* id : {"s1", "s2", "s3"}) {
      EXPECT_EQ(by_slurm.at(id)["state"], "done") << id;
      EXPECT_EQ(manifest_digests(on_slurm / id), manifest_digests(local / id)) << id << ": Slurm and local differ";
      EXPECT_EQ(file_digests(on_slurm / id, "manifest.json"), file_digests(local / id, "manifest.json")) << id;
    }
    EXPECT_EQ(by_slurm.at("broken")["exit_code"], 10);
    const std::string script = read_file(on_slurm / "cohort" / "cohort.sbatch");
    EXPECT_NE(script.find("#SBATCH --array=0-3"), std::string::npos) << script;
    EXPECT_NE(script.find("#SBATCH --job-name=organsmith-cohort"), std::string::npos);
    expect_no_input_path(on_slurm);

    const CliResult rerun = run_cli(args + " --engine slurm --out " + quoted(on_slurm));
    EXPECT_EQ(rerun.exit_code, 80) << rerun.output;
    for (const char* id : {"s1", "s2", "s3"}) EXPECT_EQ(studies_by_id(on_slurm).at(id)["state"], "reused") << id;
  }
  EXPECT_FALSE(fs::exists(slurm_dir / "run" / "slurmctld.pid")) << "the cluster's daemons were stopped";
}

TEST(Cohort, AStudyKilledMidRunIsCompletedByTheRerun) {
  ScratchDir tmp("cohort-kill");
  write(tmp / "shared.toml", kSmallCase);
  write(tmp / "cohort.csv", "id,input,phantom.seed\nk1,phantom,1\n");
  const fs::path out = tmp / "out";
  const std::string args = "cohort " + quoted(tmp / "cohort.csv") + " --case " + quoted(tmp / "shared.toml") +
                           " --poll-s 0.2 --out " + quoted(out);

  // Local pool, no retries: the killed study is reported, and the rerun completes it.
  std::thread killer([&] { EXPECT_TRUE(kill_study_mid_run(out, "k1", 0)) << "the study never started"; });
  const CliResult r = run_cli(args + " --retries 0");
  killer.join();
  EXPECT_EQ(r.exit_code, 80) << r.output;
  auto s = studies_by_id(out).at("k1");
  EXPECT_EQ(s["state"], "failed");
  EXPECT_EQ(s["exit_code"], 128 + SIGKILL);
  EXPECT_NE(s["message"].get<std::string>().find("without a status"), std::string::npos) << s.dump();
  const CliResult rerun = run_cli(args);
  EXPECT_EQ(rerun.exit_code, 0) << rerun.output;
  EXPECT_EQ(studies_by_id(out).at("k1")["state"], "done");
  expect_complete(out / "k1");

  // On Slurm, a task killed mid-run is retried within the same cohort run.
  SlurmCluster cluster;
  if (cluster.missing_tools()) GTEST_SKIP() << "Slurm is not installed (scripts/install-deps installs slurm-wlm, munge)";
  ASSERT_TRUE(cluster.up()) << cluster.start_log();
  const fs::path on_slurm = tmp / "slurm";
  const std::string slurm_args = "cohort " + quoted(tmp / "cohort.csv") + " --case " + quoted(tmp / "shared.toml") +
                                 " --poll-s 0.2 --engine slurm --retries 1 --out " + quoted(on_slurm);
  std::thread slurm_killer([&] { EXPECT_TRUE(kill_study_mid_run(on_slurm, "k1", 0)); });
  const CliResult sr = run_cli(slurm_args);
  slurm_killer.join();
  EXPECT_EQ(sr.exit_code, 0) << sr.output;
  s = studies_by_id(on_slurm).at("k1");
  EXPECT_EQ(s["state"], "done");
  EXPECT_EQ(s["attempts"], 2);
  expect_complete(on_slurm / "k1");
  EXPECT_EQ(manifest_digests(on_slurm / "k1"), manifest_digests(out / "k1"));
}

TEST(Cohort, AControllerStoppedMidCohortIsExit81AndTheRerunRunsNoStudyTwice) {
  SlurmCluster cluster;
  if (cluster.missing_tools()) GTEST_SKIP() << "Slurm is not installed (scripts/install-deps installs slurm-wlm, munge)";
  ASSERT_TRUE(cluster.up()) << cluster.start_log();
  ScratchDir tmp("cohort-ctld");
  write(tmp / "shared.toml", kSmallCase);
  write(tmp / "cohort.csv", "id,input,phantom.seed\nc1,phantom,1\nc2,phantom,2\nc3,phantom,3\n");
  const fs::path out = tmp / "out";
  // One study at a time, so that the later ones wait in the queue while the controller is away.
  const std::string args = "cohort " + quoted(tmp / "cohort.csv") + " --case " + quoted(tmp / "shared.toml") +
                           " --engine slurm --jobs 1 --poll-s 0.2 --out " + quoted(out);
  auto controller = [&](const char* what) { return cluster.command(what, tmp / "controller.log"); };

  // The controller stops while the first study runs: the cohort waits 3 s for it, then exit 81.
  std::thread stopper([&] {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (study_process(out, 0) == 0 && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    EXPECT_EQ(controller("stop-controller"), 0);
  });
  const CliResult r = run_cli(args + " --scheduler-wait-s 3");
  stopper.join();
  EXPECT_EQ(r.exit_code, 81) << r.output;
  EXPECT_NE(r.output.find("the Slurm controller has not answered"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("none runs twice"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(out / "cohort" / "slurm_arrays.json")) << "the submitted array is remembered";
  const std::string first_job = read_json(out / "cohort" / "slurm_arrays.json")["arrays"][0]["job"];

  // Controller back: the rerun waits for the tasks of the first array, submits nothing new, and
  // every study has run exactly once.
  ASSERT_EQ(controller("start-controller"), 0) << read_file(tmp / "controller.log");
  const CliResult again = run_cli(args);
  EXPECT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("still queued or running; waiting for them"), std::string::npos) << again.output;
  const auto summary = read_json(out / "cohort.json");
  EXPECT_EQ(summary["slurm_jobs"], nlohmann::json::array({first_job})) << "no study was submitted again";
  for (const char* id : {"c1", "c2", "c3"}) {
    const auto s = studies_by_id(out).at(id);
    EXPECT_TRUE(s["state"] == "done" || s["state"] == "reused") << s.dump();
    expect_complete(out / id);
    const std::string log = read_file(out / "cohort" / "logs" / (std::string(id) + ".log"));
    std::size_t runs = 0;
    for (auto at = log.find("cohort study '"); at != std::string::npos; at = log.find("cohort study '", at + 1))
      runs += log.compare(at, 20 + std::strlen(id), "cohort study '" + std::string(id) + "' (row") == 0;
    EXPECT_EQ(runs, 1u) << id << " ran " << runs << " times:\n" << log;
  }
  EXPECT_FALSE(fs::exists(out / "cohort" / "slurm_arrays.json")) << "every array was collected";
}

// A disk that fills while a cohort runs: each study that meets it ends in exit 30 with nothing
// half-written (no staging folder, no partial summary); with room again, the same command completes
// every study.
TEST(Cohort, AFullDiskFailsItsStudiesWithExit30AndTheRerunCompletesThem) {
  organsmith::testing::SmallDisk disk("cohortdisk", 32 * 1024);
  if (!disk.mounted()) GTEST_SKIP() << disk.why();
  ScratchDir tmp("cohort-disk");
  write(tmp / "shared.toml", kSmallCase);
  write(tmp / "cohort.csv", "id,input,phantom.seed\nf1,phantom,1\nf2,phantom,2\n");
  const fs::path out = disk / "out";
  const std::string args = "cohort " + quoted(tmp / "cohort.csv") + " --case " + quoted(tmp / "shared.toml") +
                           " --jobs 1 --poll-s 0.2 --out " + quoted(out);
  {  // 3 MiB left: a study's folder needs about 6.5 MiB
    const std::uintmax_t keep = 3u << 20, available = fs::space(disk.path()).available;
    ASSERT_GT(available, keep);
    std::ofstream filler(disk / "filler", std::ios::binary);
    const std::string chunk(1u << 16, 'x');
    for (std::uintmax_t left = available - keep; left >= chunk.size(); left -= chunk.size())
      filler.write(chunk.data(), std::streamsize(chunk.size()));
  }
  const CliResult full = run_cli(args);
  EXPECT_TRUE(full.exit_code == 80 || full.exit_code == 30) << full.output;
  EXPECT_NE(full.output.find("exit 30"), std::string::npos) << full.output;
  EXPECT_FALSE(has_staging_leftover(out)) << "a staging folder was left on the full disk";
  if (fs::exists(out / "cohort.json")) {
    for (const auto& [id, s] : studies_by_id(out)) {
      EXPECT_EQ(s["state"], "failed") << s.dump();
      EXPECT_EQ(s["exit_code"], 30) << s.dump();
      EXPECT_EQ(s["attempts"], 1) << "a full disk is not retried: " << s.dump();
    }
  }

  fs::remove(disk / "filler");
  const CliResult again = run_cli(args);
  ASSERT_EQ(again.exit_code, 0) << again.output;
  for (const char* id : {"f1", "f2"}) {
    EXPECT_EQ(studies_by_id(out).at(id)["state"], "done") << id;
    expect_complete(out / id);
  }
  EXPECT_FALSE(has_staging_leftover(out));
}
