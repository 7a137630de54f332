// The two cohort engines (a local process pool, a Slurm job array) and what they share: reuse of
// completed studies, retries, progress, and the summary at the end.
#include "pipeline/cohort_engine.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "core/format.h"
#include "core/process.h"
#include "pipeline/cohort_summary.h"
#include "pipeline/output_dir.h"
#include "pipeline/output_layout.h"
#include "pipeline/runner.h"

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

namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::optional<StudyStatus> read_status(const fs::path& file) {
  const auto text = read_file(file);
  if (!text) return std::nullopt;
  try {
    return study_status_from_json(nlohmann::json::parse(*text));
  } catch (const nlohmann::json::exception&) {
    return std::nullopt;
  }
}

/// The largest peak RSS (MiB) and run time (s) over the cohort's studies that have a manifest.
std::pair<double, double> measured_study_cost(const CohortPlan& plan) {
  double rss = 0, seconds = 0;
  const CohortLayout layout{plan.out_dir};
  for (const auto& s : plan.studies) {
    const auto text = read_file(OutputLayout{layout.study(s.id)}.manifest());
    if (!text) continue;
    try {
      const auto m = nlohmann::json::parse(*text);
      double total = 0;
      for (const auto& st : m.at("stages")) {
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

class Tally {
 public:
  Tally(Progress& p, std::size_t total) : progress_(p), total_(total) {}
  void show(std::size_t done, std::size_t running, std::size_t failed) {
    progress_.report(total_ ? double(done + failed) / double(total_) : 1.0,
                     "studies: " + std::to_string(done) + " done, " + std::to_string(running) + " running, " +
                         std::to_string(failed) + " failed of " + std::to_string(total_));
  }

 private:
  Progress& progress_;
  std::size_t total_;
};

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

// ---- Slurm engine -------------------------------------------------------------------------------

class SchedulerError : public Error {
 public:
  SchedulerError(std::string message, std::string hint) : Error(ExitCode::scheduler, std::move(message), {}, std::move(hint)) {}
};

fs::path slurm_tool(const std::string& name) {
  const fs::path p = find_on_path(name);
  if (p.empty())
    throw SchedulerError("Slurm's '" + name + "' is not on PATH",
                         "run on a Slurm login node, or use --engine local (Debian: apt-get install slurm-client)");
  return p;
}

std::string trim(std::string s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
  return s.substr(std::min(s.size(), s.find_first_not_of(" \t\r\n")));
}

/// Final state and exit code of array task `index` of `job`, from sacct (or scontrol while the
/// controller still holds the job). Nothing when neither knows.
std::optional<std::pair<std::string, int>> finished_task_state(const std::string& job, std::size_t index) {
  const std::string task = job + "_" + std::to_string(index);
  if (const fs::path sacct = find_on_path("sacct"); !sacct.empty()) {
    const auto r = run_command(sacct, {"-n", "-P", "-X", "-j", task, "-o", "State,ExitCode"}, 30);
    if (r.exit_code == 0) {
      std::istringstream in(r.output);
      std::string line;
      if (std::getline(in, line) && line.find('|') != std::string::npos) {
        const std::string state = trim(line.substr(0, line.find('|')));
        const std::string code = line.substr(line.find('|') + 1);
        const int exit = std::atoi(code.c_str()), sig = std::atoi(code.substr(code.find(':') + 1).c_str());
        return std::make_pair(state.substr(0, state.find(' ')), sig ? 128 + sig : exit);
      }
    }
  }
  const auto r = run_command(slurm_tool("scontrol"), {"show", "job", task}, 30);
  const auto state_at = r.output.find("JobState="), code_at = r.output.find(" ExitCode=");
  if (r.exit_code != 0 || state_at == std::string::npos || code_at == std::string::npos) return std::nullopt;
  std::string state = r.output.substr(state_at + 9);
  state = state.substr(0, state.find_first_of(" \n"));
  const std::string code = r.output.substr(code_at + 10);
  const int exit = std::atoi(code.c_str()), sig = std::atoi(code.substr(code.find(':') + 1).c_str());
  return std::make_pair(state, sig ? 128 + sig : exit);
}

std::string array_list(const std::vector<std::size_t>& todo) {
  std::string list;
  for (std::size_t i : todo) list += (list.empty() ? "" : ",") + std::to_string(i);
  return list;
}

std::vector<StudyOutcome> run_slurm(const CohortPlan& plan, const std::vector<std::size_t>& todo,
                                    const CohortOptions& o, Progress& progress, std::vector<std::string>& jobs_out) {
  const CohortLayout layout{plan.out_dir};
  const fs::path sbatch = slurm_tool("sbatch"), squeue = slurm_tool("squeue"), scancel = slurm_tool("scancel");
  std::string array = "--array=" + array_list(todo);
  if (o.jobs > 0) array += "%" + std::to_string(o.jobs);
  const auto submitted = run_command(sbatch, {"--parsable", array, layout.slurm_script().string()}, 120);
  if (submitted.exit_code != 0)
    throw SchedulerError("sbatch refused the cohort's job array: " + trim(submitted.output),
                         "check the partition, account, QOS and limits (--partition, --account, --qos, --mem-mb)");
  const std::string job = trim(submitted.output).substr(0, trim(submitted.output).find(';'));
  jobs_out.push_back(job);
  spdlog::info("cohort: submitted Slurm job array {} ({} tasks); script {}", job, todo.size(),
               layout.slurm_script().string());

  std::map<std::size_t, StudyOutcome> finished;
  std::map<std::size_t, int> absent_polls;  // polls in which a task was neither queued nor had a status
  std::size_t failed = 0;
  int squeue_failures = 0;
  Tally tally(progress, todo.size());
  while (finished.size() < todo.size()) {
    if (progress.cancelled()) {
      run_command(scancel, {job}, 30);
      throw Cancelled();
    }
    const auto q = run_command(squeue, {"-h", "-r", "-j", job, "-o", "%K %T"}, 60);
    std::set<std::size_t> active;
    std::size_t running = 0;
    if (q.exit_code != 0 && q.output.find("Invalid job id") == std::string::npos) {
      if (++squeue_failures >= 30)
        throw SchedulerError("squeue cannot reach the Slurm controller: " + trim(q.output),
                             "the job array " + job + " may still run; rerun the cohort to collect it");
      std::this_thread::sleep_for(std::chrono::milliseconds(int(1000 * o.poll_s)));
      continue;  // no answer is not "every task has left the queue"
    } else {
      squeue_failures = 0;
      std::istringstream in(q.output);
      std::size_t k;
      std::string state;
      while (in >> k >> state) {
        active.insert(k);
        if (state == "RUNNING" || state == "COMPLETING") ++running;
      }
    }
    for (std::size_t index : todo) {
      if (finished.count(index) || active.count(index)) continue;
      const auto& s = plan.studies[index];
      const auto status = read_status(layout.status(s.id));
      if (!status && ++absent_polls[index] < 3) continue;  // the status file may be on its way
      const auto state = status ? std::nullopt : finished_task_state(job, index);
      static const std::set<std::string> still_going = {"PENDING", "CONFIGURING", "RUNNING", "COMPLETING", "SUSPENDED",
                                                        "REQUEUED", "RESIZING"};
      if (state && still_going.count(state->first)) continue;  // squeue missed it: not over yet
      StudyOutcome out = outcome_from_status(
          s.id, status, state ? state->second : -1,
          state ? "Slurm task " + job + "_" + std::to_string(index) + " ended " + state->first
                : "Slurm task " + job + "_" + std::to_string(index) + " left the queue");
      if (out.state == "failed") ++failed;
      finished[index] = out;
    }
    tally.show(finished.size() - failed, running, failed);
    if (finished.size() < todo.size()) std::this_thread::sleep_for(std::chrono::milliseconds(int(1000 * o.poll_s)));
  }
  std::vector<StudyOutcome> out;
  for (auto& [i, oc] : finished) out.push_back(oc);
  return out;
}

}  // namespace

std::string slurm_script(const CohortPlan& plan, const CohortOptions& o, int cpus, double memory_mb,
                         double time_limit_min) {
  const CohortLayout layout{plan.out_dir};
  auto q = [](const std::string& s) {
    std::string out = "'";
    for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
  };
  std::ostringstream s;
  s << "#!/bin/bash\n"
    << "# organsmith cohort: one array task per study; task N runs study N of cohort/plan.json.\n"
    << "# organsmith submits it with --array=<the studies to run>; to resubmit by hand:\n"
    << "#   sbatch --array=3,5 " << layout.slurm_script().string() << "\n"
    << "#SBATCH --job-name=organsmith-cohort\n"
    << "#SBATCH --array=0-" << plan.studies.size() - 1 << (o.jobs > 0 ? "%" + std::to_string(o.jobs) : "") << "\n"
    << "#SBATCH --ntasks=1\n"
    << "#SBATCH --cpus-per-task=" << cpus << "\n"
    << "#SBATCH --mem=" << std::max(64, int(std::ceil(memory_mb))) << "M\n"
    << "#SBATCH --time=" << std::max(1, int(std::ceil(time_limit_min))) << "\n"
    << "#SBATCH --output=" << layout.slurm_log_pattern().string() << "\n";
  if (!o.partition.empty()) s << "#SBATCH --partition=" << o.partition << "\n";
  if (!o.account.empty()) s << "#SBATCH --account=" << o.account << "\n";
  if (!o.qos.empty()) s << "#SBATCH --qos=" << o.qos << "\n";
  for (const auto& line : o.sbatch_lines) s << (line.rfind("#SBATCH", 0) == 0 ? line : "#SBATCH " + line) << "\n";
  s << "set -eu\n"
    << "exec " << q(self_executable().string()) << " --threads " << cpus << " cohort-study "
    << q(plan.out_dir.string()) << " \"$SLURM_ARRAY_TASK_ID\"\n";
  return s.str();
}

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
  for (std::size_t i = 0; i < plan.studies.size(); ++i) {
    const auto& s = plan.studies[i];
    const auto status = read_status(layout.status(s.id));
    StudyOutcome reused{s.id, "reused", 0, "", 0, status ? status->seconds : 0.0};
    if (!o.force && status && status->exit_code == 0 && status->fingerprint == s.fingerprint &&
        fs::exists(OutputLayout{layout.study(s.id)}.manifest())) {
      result.studies.push_back(reused);
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
