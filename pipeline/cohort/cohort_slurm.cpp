// The Slurm engine of a cohort: one job array per run, watched with squeue; the arrays a run
// submitted are kept in cohort/slurm_arrays.json until every task is collected, so that a run that
// stopped (Ctrl-C, a controller that went silent) is picked up by the next: its tasks still queued
// or running are waited for, never submitted again.
#include "core/errors.h"
#include "core/file_io.h"
#include "core/process.h"
#include "pipeline/cohort/cohort_engine_detail.h"
#include "pipeline/output/output_layout.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>
#include <thread>

namespace fs = std::filesystem;

namespace organsmith {

namespace cohort_detail {
namespace {

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

// ---- the record of submitted arrays -------------------------------------------------------------

using Arrays = std::map<std::string, std::vector<std::size_t>>;  ///< job id → study indices submitted in it

Arrays read_arrays(const CohortLayout& layout) {
  Arrays arrays;
  const auto text = read_file(layout.slurm_arrays());
  if (!text) return arrays;
  try {
    const nlohmann::json record = nlohmann::json::parse(*text);  // kept: the loop runs over its member
    for (const auto& a : record.at("arrays"))
      arrays[a.at("job").get<std::string>()] = a.at("studies").get<std::vector<std::size_t>>();
  } catch (const nlohmann::json::exception& e) {
    spdlog::warn("cohort: {} is unreadable ({}); earlier job arrays are not waited for", layout.slurm_arrays().string(),
                 e.what());
  }
  return arrays;
}

void write_arrays(const CohortLayout& layout, const Arrays& arrays) {
  if (arrays.empty()) {
    std::error_code ec;
    fs::remove(layout.slurm_arrays(), ec);
    return;
  }
  nlohmann::json list = nlohmann::json::array();
  for (const auto& [job, studies] : arrays) list.push_back({{"job", job}, {"studies", studies}});
  write_file_atomic(layout.slurm_arrays(), nlohmann::json{{"arrays", list}}.dump(1) + "\n");
}

// ---- the controller -----------------------------------------------------------------------------

/// squeue, with the time the controller has been silent: a silence longer than the cohort's
/// scheduler_wait_s is exit 81 (the arrays keep running on the nodes).
class Controller {
 public:
  explicit Controller(const CohortOptions& o) : o_(o), squeue_(slurm_tool("squeue")) {}

  /// Array task index → state of job `job`'s tasks still queued or running; nothing while the
  /// controller does not answer (the caller polls again).
  std::optional<std::map<std::size_t, std::string>> active(const std::string& job) {
    const double left = silent_since_ ? o_.scheduler_wait_s - since(*silent_since_) : o_.scheduler_wait_s;
    const auto asked = Clock::now();
    const auto q = run_command(squeue_, {"-h", "-r", "-j", job, "-o", "%K %T"}, std::clamp(left, 2.0, 60.0));
    std::map<std::size_t, std::string> tasks;
    if (q.exit_code == 0 || q.output.find("Invalid job id") != std::string::npos) {  // a forgotten job: none left
      silent_since_.reset();
      std::istringstream in(q.exit_code == 0 ? q.output : "");
      std::size_t k;
      std::string state;
      while (in >> k >> state) tasks[k] = state;
      return tasks;
    }
    if (!silent_since_) silent_since_ = asked;
    if (since(*silent_since_) >= o_.scheduler_wait_s)
      throw SchedulerError("the Slurm controller has not answered for " + std::to_string(int(since(*silent_since_))) +
                               " s (squeue: " + (trim(q.output).empty() ? "no answer" : trim(q.output)) + ")",
                           "job array " + job + " goes on running on the nodes; when the controller is back, run "
                           "the same cohort command again: studies that finished are collected, those still queued "
                           "or running are waited for, none runs twice");
    spdlog::warn("cohort: the Slurm controller does not answer (squeue: {}); trying again", trim(q.output));
    return std::nullopt;
  }

 private:
  const CohortOptions& o_;
  fs::path squeue_;
  std::optional<Clock::time_point> silent_since_;
};

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

/// Waits until every task of `arrays` (job → study indices) has ended; each job is forgotten in the
/// record once its tasks are collected. Outcomes by study index.
std::map<std::size_t, StudyOutcome> wait_for_tasks(const CohortPlan& plan, const Arrays& arrays,
                                                   const CohortOptions& o, Progress& progress) {
  const CohortLayout layout{plan.out_dir};
  Controller controller(o);
  const fs::path scancel = slurm_tool("scancel");
  std::size_t total = 0;
  for (const auto& [job, studies] : arrays) total += studies.size();
  std::map<std::size_t, StudyOutcome> finished;
  std::map<std::size_t, int> absent_polls;  // polls in which a task was neither queued nor had a status
  std::set<std::string> collected;
  std::size_t failed = 0;
  Tally tally(progress, total);
  while (finished.size() < total) {
    if (progress.cancelled()) {
      for (const auto& [job, studies] : arrays) run_command(scancel, {job}, 30);
      throw Cancelled();
    }
    std::size_t running = 0;
    for (const auto& [job, studies] : arrays) {
      if (collected.count(job)) continue;
      const auto active = controller.active(job);
      if (!active) continue;  // no answer is not "every task has left the queue"
      for (const auto& [k, state] : *active)
        if (state == "RUNNING" || state == "COMPLETING") ++running;
      for (std::size_t index : studies) {
        if (finished.count(index)) continue;
        if (active->count(index)) continue;
        const auto& s = plan.studies[index];
        const auto status = read_status(layout.status(s.id));
        if (!status && ++absent_polls[index] < 3) continue;  // the status file may be on its way
        const auto state = status ? std::nullopt : finished_task_state(job, index);
        static const std::set<std::string> still_going = {"PENDING",   "CONFIGURING", "RUNNING", "COMPLETING",
                                                          "SUSPENDED", "REQUEUED",    "RESIZING"};
        if (state && still_going.count(state->first)) continue;  // squeue missed it: not over yet
        const std::string task = "Slurm task " + job + "_" + std::to_string(index);
        StudyOutcome out = outcome_from_status(s.id, status, state ? state->second : -1,
                                               state ? task + " ended " + state->first : task + " left the queue");
        if (out.state == "failed") ++failed;
        finished[index] = out;
      }
      if (std::all_of(studies.begin(), studies.end(), [&](std::size_t i) { return finished.count(i) > 0; })) {
        collected.insert(job);
        Arrays record = read_arrays(layout);
        record.erase(job);
        write_arrays(layout, record);
      }
    }
    tally.show(finished.size() - failed, running, failed);
    if (finished.size() < total) std::this_thread::sleep_for(std::chrono::milliseconds(int(1000 * o.poll_s)));
  }
  return finished;
}

}  // namespace

std::vector<StudyOutcome> run_slurm(const CohortPlan& plan, const std::vector<std::size_t>& todo,
                                    const CohortOptions& o, Progress& progress, std::vector<std::string>& jobs) {
  const CohortLayout layout{plan.out_dir};
  const fs::path sbatch = slurm_tool("sbatch");
  std::string array = "--array=" + array_list(todo);
  if (o.jobs > 0) array += "%" + std::to_string(o.jobs);
  const auto submitted = run_command(sbatch, {"--parsable", array, layout.slurm_script().string()}, 120);
  if (submitted.exit_code != 0)
    throw SchedulerError("sbatch refused the cohort's job array: " + trim(submitted.output),
                         "check the partition, account, QOS and limits (--partition, --account, --qos, --mem-mb)");
  const std::string job = trim(submitted.output).substr(0, trim(submitted.output).find(';'));
  jobs.push_back(job);
  Arrays record = read_arrays(layout);
  record[job] = todo;
  write_arrays(layout, record);
  spdlog::info("cohort: submitted Slurm job array {} ({} tasks); script {}", job, todo.size(),
               layout.slurm_script().string());
  std::vector<StudyOutcome> out;
  for (auto& [i, oc] : wait_for_tasks(plan, {{job, todo}}, o, progress)) out.push_back(oc);
  return out;
}

std::vector<std::pair<std::size_t, StudyOutcome>> collect_earlier_slurm_arrays(const CohortPlan& plan,
                                                                               const CohortOptions& o,
                                                                               Progress& progress,
                                                                               std::vector<std::string>& jobs) {
  const CohortLayout layout{plan.out_dir};
  Arrays record = read_arrays(layout);
  if (record.empty()) return {};
  Controller controller(o);
  Arrays waiting;
  for (auto it = record.begin(); it != record.end();) {
    std::optional<std::map<std::size_t, std::string>> active;
    while (!(active = controller.active(it->first))) std::this_thread::sleep_for(std::chrono::milliseconds(int(1000 * o.poll_s)));
    std::vector<std::size_t> left;
    for (std::size_t i : it->second)
      if (active->count(i) && i < plan.studies.size()) left.push_back(i);
    if (left.empty()) {
      it = record.erase(it);  // over: the status files tell how each study ended
      continue;
    }
    spdlog::info("cohort: {} studies of Slurm job array {} (an earlier run) are still queued or running; waiting "
                 "for them instead of submitting them again",
                 left.size(), it->first);
    waiting[it->first] = left;
    jobs.push_back(it->first);
    ++it;
  }
  write_arrays(layout, record);
  std::vector<std::pair<std::size_t, StudyOutcome>> out;
  if (waiting.empty()) return out;
  for (auto& [i, oc] : wait_for_tasks(plan, waiting, o, progress)) out.emplace_back(i, oc);
  return out;
}

}  // namespace cohort_detail

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

}  // namespace organsmith
