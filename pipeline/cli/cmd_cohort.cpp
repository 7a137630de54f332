// `organsmith cohort COHORT --out DIR`: one case over many studies (pipeline/cohort/cohort.h), and the
// hidden `organsmith cohort-study DIR INDEX` that runs one study in its own process.

#include "pipeline/cohort/cohort.h"
#include "pipeline/cohort/cohort_engine.h"
#include "pipeline/cli/commands.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/run/terminal_progress.h"

#include "core/errors.h"
#include "core/file_io.h"

#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <unistd.h>

#include <cstdio>
#include <iostream>
#include <memory>
#include <mutex>

namespace organsmith {
namespace fs = std::filesystem;

namespace {

struct CohortArgs {
  std::string cohort, case_file, out;
  CohortOptions options;
  bool no_submit = false;
};

/// Log lines of a study with its input path replaced (a folder may be named after a patient).
class RedactingSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  explicit RedactingSink(CohortStudy study) : study_(std::move(study)) {}

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    spdlog::memory_buf_t buf;
    formatter_->format(msg, buf);
    const std::string line = redact_study_text(study_, fmt::to_string(buf));
    std::fwrite(line.data(), 1, line.size(), stderr);
  }
  void flush_() override { std::fflush(stderr); }

 private:
  CohortStudy study_;
};

CohortPlan read_plan(const fs::path& dir) {
  const CohortLayout layout{fs::absolute(dir)};
  const auto text = read_file(layout.plan());
  if (!text)
    throw InputError(ExitCode::input_not_found, "no cohort plan in this directory", layout.plan(),
                     "give the --out directory of `organsmith cohort`");
  try {
    return cohort_plan_from_json(nlohmann::json::parse(*text), layout.plan());
  } catch (const nlohmann::json::exception& e) {
    throw InputError(ExitCode::corrupt_file, std::string("the cohort plan is not JSON: ") + e.what(), layout.plan(),
                     "rerun `organsmith cohort` to write it again");
  }
}

int cmd_cohort_study(const std::string& dir, std::size_t index) {
  const CohortPlan plan = read_plan(dir);
  if (index >= plan.studies.size())
    throw UsageError("study " + std::to_string(index) + " is not in the cohort (it has " +
                     std::to_string(plan.studies.size()) + ")");
  const CohortStudy& study = plan.studies[index];
  const CohortLayout layout{plan.out_dir};
  // Everything the study prints goes to its own log, through the redacting sink.
  fs::create_directories(layout.log(study.id).parent_path());
  const int fd = open(layout.log(study.id).c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  if (fd < 0) throw OutputError("cannot open the study's log", layout.log(study.id));
  std::fflush(stdout);
  std::fflush(stderr);
  dup2(fd, 1);
  dup2(fd, 2);
  close(fd);
  auto logger = std::make_shared<spdlog::logger>("organsmith", std::make_shared<RedactingSink>(study));
  logger->set_pattern("%Y-%m-%d %H:%M:%S [%l] %v");
  logger->set_level(spdlog::get_level());
  spdlog::set_default_logger(logger);
  return run_cohort_study(plan, index);
}

int cmd_cohort(CohortArgs& a) {
  a.options.submit = !a.no_submit;
  const CohortPlan plan = load_cohort(a.cohort, a.case_file, a.out);
  spdlog::info("cohort: {} studies from {} → {} ({} engine)", plan.studies.size(), a.cohort, plan.out_dir.string(),
               a.options.engine);
  TerminalProgress progress(spdlog::get_level() >= spdlog::level::warn);
  const CohortResult r = run_cohort(plan, a.options, progress);
  progress.finish();
  const CohortLayout layout{plan.out_dir};
  std::size_t done = 0, reused = 0;
  for (const auto& s : r.studies) {
    done += s.state == "done";
    reused += s.state == "reused";
  }
  std::cout << "cohort: " << done << " done, " << reused << " reused, " << r.failed() << " failed of "
            << r.studies.size() << " studies in " << int(r.seconds + 0.5) << " s\n";
  for (const auto& s : r.studies)
    if (s.state == "failed")
      std::cout << "  " << s.id << ": exit " << s.exit_code << " — " << s.message << "\n    log: "
                << layout.log(s.id).string() << "\n";
  if (a.options.engine == "slurm" && !a.options.submit)
    std::cout << "  Slurm script (not submitted): " << layout.slurm_script().string() << "\n";
  std::cout << "  " << layout.summary_csv().string() << "\n  " << layout.summary_json().string() << "\n  "
            << layout.contact_sheet().string() << "\n";
  return r.failed() ? int(ExitCode::cohort_incomplete) : 0;
}

}  // namespace

std::vector<Command> cohort_commands(CLI::App& app) {
  auto a = std::make_shared<CohortArgs>();
  auto* cmd = app.add_subcommand(
      "cohort",
      "Run one case over many studies: every row of a cohort file (CSV, header at least id,input)\n"
      "becomes DIR/<id>/, a complete run. --engine local runs the studies here, several at a time\n"
      "(by cores and by the memory a study needs); --engine slurm submits one Slurm job array and\n"
      "follows it. A failing study never stops the others; studies that completed with the same\n"
      "case and input are reused on a rerun. Writes DIR/cohort.csv, cohort.json and cohort.png\n"
      "(a contact sheet). Exit 80 when some studies failed (cohort.csv says why), 81 when Slurm\n"
      "refuses or cannot be reached. See README.md, 'Cohorts'.");
  cmd->add_option("COHORT", a->cohort, "cohort file (CSV): id,input[,organs,seed_lps_mm.<organ>,reference.<organ>,"
                                       "<table>.<key>…]")->required();
  cmd->add_option("--case", a->case_file, "shared case file: options for every study (default: the embedded case)");
  cmd->add_option("--out", a->out, "output directory: new, empty, or a cohort's earlier output")->required();
  cmd->add_option("--engine", a->options.engine, "local (default) or slurm")->check(CLI::IsMember({"local", "slurm"}));
  cmd->add_option("--cpus-per-study", a->options.cpus_per_study, "threads per study (default: cores ÷ studies, ≥ 1)")
      ->check(CLI::Range(1, 1024));
  cmd->add_option("--mem-mb", a->options.memory_mb_per_study,
                  "memory per study in MB (default: 1.25 × the largest peak measured in this cohort, else 2048)")
      ->check(CLI::Range(64.0, 1.0e7));
  cmd->add_option("--jobs", a->options.jobs,
                  "studies at a time (local default: by cores and free memory; slurm: the array's %K limit)")
      ->check(CLI::Range(1, 100000));
  cmd->add_option("--retries", a->options.retries,
                  "reruns of a study that was killed, timed out or crashed (default 1; bad inputs are not retried)")
      ->check(CLI::Range(0, 100));
  cmd->add_flag("--force", a->options.force, "rerun studies that completed before with the same case and input");
  cmd->add_option("--time-min", a->options.time_limit_min,
                  "slurm: time limit per study in minutes (default: 3 × the slowest study so far, ≥ 30; else 120)")
      ->check(CLI::Range(1.0, 1.0e6));
  cmd->add_option("--partition", a->options.partition, "slurm: partition");
  cmd->add_option("--account", a->options.account, "slurm: account");
  cmd->add_option("--qos", a->options.qos, "slurm: quality of service");
  cmd->add_option("--sbatch", a->options.sbatch_lines, "slurm: a further #SBATCH directive, e.g. --sbatch=--constraint=avx2 (repeatable)");
  cmd->add_flag("--no-submit", a->no_submit, "slurm: write cohort/cohort.sbatch and the plan, do not submit");
  cmd->add_option("--poll-s", a->options.poll_s, "seconds between looks at the running studies (default 1)")
      ->check(CLI::Range(0.05, 600.0));
  cmd->add_option("--scheduler-wait-s", a->options.scheduler_wait_s,
                  "slurm: how long the controller may stay silent before the cohort stops with exit 81 (default 600); "
                  "the job array goes on running, and the same command run again collects it without running any "
                  "study twice")
      ->check(CLI::Range(1.0, 86400.0));

  auto study = std::make_shared<std::pair<std::string, std::size_t>>();
  auto* task = app.add_subcommand("cohort-study", "Run one study of a cohort (what each cohort task runs)");
  task->group("");  // internal: not listed in --help
  task->add_option("DIR", study->first, "the cohort's output directory")->required();
  task->add_option("INDEX", study->second, "the study's index in cohort/plan.json")->required();
  return {{cmd, [a] { return cmd_cohort(*a); }}, {task, [study] { return cmd_cohort_study(study->first, study->second); }}};
}

}  // namespace organsmith
