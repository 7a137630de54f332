// A cohort's run: reuse of completed studies, the local process pool, retries, progress and the
// summary at the end (the Slurm engine is in cohort_slurm.cpp).
#include "pipeline/cohort/cohort_engine.h"
#include "pipeline/output/tool_info.h"
#include "pipeline/cohort/cohort_engine_detail.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "core/format.h"
#include "core/process.h"
#include "pipeline/cohort/cohort_summary.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/output/output_layout.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;

namespace organsmith {

int CohortResult::failed() const {
  return int(std::count_if(studies.begin(), studies.end(), [](const StudyOutcome& s) { return s.state == "failed"; }));
}

namespace cohort_detail {

std::optional<StudyStatus> read_status(const fs::path& file) {
  const auto text = read_file(file);
  if (!text) return std::nullopt;
  try {
    return study_status_from_json(nlohmann::json::parse(*text));
  } catch (const nlohmann::json::exception&) {
    return std::nullopt;
  }
}

StudyOutcome outcome_from_status(const std::string& id, const std::optional<StudyStatus>& status, int process_code,
                                 const std::string& ended_how) {
  StudyOutcome o;
  o.id = id;
  if (status) {
    o.exit_code = status->exit_code;
    o.message = status->message;
    o.seconds = status->seconds;
  } else {
    o.exit_code = process_code;
    o.message = "the study's process ended without a status: " + ended_how;
  }
  o.state = o.exit_code == 0 ? "done" : "failed";
  return o;
}

void Tally::show(std::size_t done, std::size_t running, std::size_t failed) {
  progress_.report(total_ ? double(done + failed) / double(total_) : 1.0,
                   "studies: " + std::to_string(done) + " done, " + std::to_string(running) + " running, " +
                       std::to_string(failed) + " failed of " + std::to_string(total_));
}

}  // namespace cohort_detail

namespace {

using namespace cohort_detail;

/// The largest peak RSS (MiB) and run time (s) over the cohort's studies that have a manifest.
std::pair<double, double> measured_study_cost(const CohortPlan& plan) {
  double rss = 0, seconds = 0;
  const CohortLayout layout{plan.out_dir};
  for (const auto& s : plan.studies) {
    const auto m = read_manifest(layout.study(s.id));
    if (!m) continue;
    try {
      double total = 0;
      for (const auto& st : m->at("stages")) {
        rss = std::max(rss, st.value("peak_rss_mib", 0.0));
        total += st.value("seconds", 0.0);
      }
      seconds = std::max(seconds, total);
    } catch (const nlohmann::json::exception&) {
    }
  }
  return {rss, seconds};
}

double available_memory_mb() {
  std::ifstream f("/proc/meminfo");
  for (std::string line; std::getline(f, line);)
    if (line.rfind("MemAvailable:", 0) == 0) return std::stod(line.substr(13)) / 1024.0;
  return 4096.0;
}

/// A study failed for a reason a rerun may not meet again (killed, out of time, crashed, no status).
bool worth_retrying(int exit_code) {
  return exit_code < 0 || exit_code == int(ExitCode::internal) || exit_code >= 128;
}

// ---- local engine -------------------------------------------------------------------------------

std::vector<StudyOutcome> run_local(const CohortPlan& plan, const std::vector<std::size_t>& todo, int cpus,
                                    double memory_mb, const CohortOptions& o, Progress& progress) {
  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  int jobs = o.jobs > 0 ? o.jobs
                        : std::max(1, std::min(cores / cpus, int(available_memory_mb() * 0.8 / std::max(1.0, memory_mb))));
  spdlog::info("cohort: {} studies, {} at a time, {} thread(s) and ~{} MB each", todo.size(), jobs, cpus,
               int(memory_mb));
  const CohortLayout layout{plan.out_dir};
  const fs::path exe = self_executable();
  struct Running {
    std::size_t index;
    std::unique_ptr<ChildProcess> child;
  };
  std::vector<Running> running;
  std::vector<StudyOutcome> out;
  std::size_t next = 0, failed = 0;
  Tally tally(progress, todo.size());
  while (next < todo.size() || !running.empty()) {
    if (progress.cancelled()) {
      for (auto& r : running) r.child->signal(SIGTERM);
      for (auto& r : running) r.child->wait();
      throw Cancelled();
    }
    while (next < todo.size() && int(running.size()) < jobs) {
      const std::size_t index = todo[next++];
      ChildSpec spec;
      spec.exe = exe;
      spec.args = {"--threads", std::to_string(cpus), "cohort-study", plan.out_dir.string(), std::to_string(index)};
      spec.log = "/dev/null";  // the study writes its own log (cohort/logs/<id>.log)
      spec.own_process_group = true;
      running.push_back({index, std::make_unique<ChildProcess>(spec)});
    }
    for (auto it = running.begin(); it != running.end();) {
      if (auto code = it->child->poll()) {
        const auto& s = plan.studies[it->index];
        out.push_back(outcome_from_status(s.id, read_status(layout.status(s.id)), *code,
                                          "exit code " + std::to_string(*code)));
        if (out.back().state == "failed") ++failed;
        it = running.erase(it);
      } else {
        ++it;
      }
    }
    tally.show(out.size() - failed, running.size(), failed);
    std::this_thread::sleep_for(std::chrono::milliseconds(int(1000 * std::min(o.poll_s, 0.2))));
  }
  return out;
}

}  // namespace

CohortResult run_cohort(const CohortPlan& plan, const CohortOptions& o, Progress& progress) {
  if (o.engine != "local" && o.engine != "slurm")
    throw UsageError("unknown cohort engine '" + o.engine + "'", "use --engine local or --engine slurm");
  const auto t0 = Clock::now();
  const CohortLayout layout{plan.out_dir};
  OutputDirOptions dir_options;
  dir_options.command = "cohort";
  dir_options.inputs = {plan.cohort_file, plan.shared_case};
  for (const auto& s : plan.studies)
    if (s.input != "phantom" && s.input.rfind("pacs://", 0) != 0) dir_options.inputs.push_back(s.input);
  OutputDir dir(plan.out_dir, dir_options);

  // What is left to do: studies that completed with the same fingerprint are reused.
  CohortResult result;
  std::vector<std::size_t> todo;
  const auto completed = [&](std::size_t i) {
    const auto& s = plan.studies[i];
    const auto status = read_status(layout.status(s.id));
    return status && status->exit_code == 0 && status->fingerprint == s.fingerprint &&
           fs::exists(OutputLayout{layout.study(s.id)}.manifest());
  };
  for (std::size_t i = 0; i < plan.studies.size(); ++i) {
    const auto& s = plan.studies[i];
    if (!o.force && completed(i)) {
      result.studies.push_back({s.id, "reused", 0, "", 0, read_status(layout.status(s.id))->seconds});
    } else {
      result.studies.push_back({s.id, "not submitted", -1, "", 0, 0.0});
      todo.push_back(i);
    }
  }
  const auto [measured_rss, measured_s] = measured_study_cost(plan);
  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  const int cpus = o.cpus_per_study > 0 ? o.cpus_per_study
                                        : std::max(1, cores / std::max<int>(1, int(std::max<std::size_t>(todo.size(), 1))));
  const double memory_mb = o.memory_mb_per_study > 0 ? o.memory_mb_per_study
                           : measured_rss > 0      ? measured_rss * 1.25
                                                   : 2048.0;
  const double minutes = o.time_limit_min > 0 ? o.time_limit_min : measured_s > 0 ? std::max(30.0, 3 * measured_s / 60) : 120.0;

  dir.set_header({{"tool", {{"name", "organsmith"}, {"version", tool_version()}, {"git_commit", tool_git_commit()}}},
                  {"cohort", {{"studies", plan.studies.size()}, {"engine", o.engine}}}});
  dir.commit("cohort-plan", [&](const fs::path& staging) {
    const CohortLayout st{staging};
    fs::create_directories(st.work_dir());
    write_file_atomic(st.plan(), to_json(plan).dump(1) + "\n");
    if (o.engine == "slurm") write_file_atomic(st.slurm_script(), slurm_script(plan, o, cpus, memory_mb, minutes));
  });
  if (o.engine == "slurm") fs::permissions(layout.slurm_script(), fs::perms::owner_exec, fs::perm_options::add);
  fs::create_directories(layout.work_dir() / "status");
  fs::create_directories(layout.work_dir() / "logs");

  std::map<std::string, std::size_t> position;
  for (std::size_t i = 0; i < plan.studies.size(); ++i) position[plan.studies[i].id] = i;
  const bool run_now = o.engine == "local" || o.submit;
  if (run_now && o.engine == "slurm") {
    // Tasks an earlier run left queued or running (it stopped, or the controller went silent): waited
    // for here, never submitted a second time.
    for (const auto& [i, oc] : collect_earlier_slurm_arrays(plan, o, progress, result.slurm_jobs)) {
      const auto at = std::find(todo.begin(), todo.end(), i);
      if (at == todo.end()) continue;  // reused, or rerun on purpose (--force) after it
      result.studies[i] = oc;
      result.studies[i].attempts = 1;
      if (oc.state == "done" ? completed(i) : !worth_retrying(oc.exit_code)) todo.erase(at);
    }
    // A task of an earlier array may have ended between the look at the statuses and squeue's answer.
    for (auto it = todo.begin(); it != todo.end();) {
      if (o.force || result.studies[*it].attempts > 0 || !completed(*it)) {
        ++it;
        continue;
      }
      result.studies[*it] = {plan.studies[*it].id, "reused", 0, "", 0, read_status(layout.status(plan.studies[*it].id))->seconds};
      it = todo.erase(it);
    }
  }
  for (int attempt = 1; run_now && !todo.empty() && attempt <= 1 + std::max(0, o.retries); ++attempt) {
    for (std::size_t i : todo) fs::remove(layout.status(plan.studies[i].id));
    const auto outcomes = o.engine == "local" ? run_local(plan, todo, cpus, memory_mb, o, progress)
                                              : run_slurm(plan, todo, o, progress, result.slurm_jobs);
    std::vector<std::size_t> again;
    for (const auto& oc : outcomes) {
      const std::size_t i = position[oc.id];
      StudyOutcome& r = result.studies[i];
      const int attempts = r.attempts + 1;
      r = oc;
      r.attempts = attempts;
      if (oc.state == "failed") {
        spdlog::warn("cohort: study '{}' failed (exit {}, attempt {}): {}", oc.id, oc.exit_code, attempts, oc.message);
        if (worth_retrying(oc.exit_code)) again.push_back(i);
      }
    }
    std::sort(again.begin(), again.end());
    todo = again;
  }

  result.seconds = since(t0);
  dir.commit("cohort", [&](const fs::path& staging) { write_cohort_summary(plan, result, staging, progress); });
  return result;
}

}  // namespace organsmith
