#pragma once
// What the two cohort engines share (cohort_engine.cpp: the local pool and the run; cohort_slurm.cpp:
// the Slurm job arrays). Internal to the cohort code.

#include "pipeline/cohort/cohort.h"
#include "pipeline/cohort/cohort_engine.h"

#include <chrono>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace organsmith::cohort_detail {

using Clock = std::chrono::steady_clock;

inline double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// The status a study's process wrote at its end, or nothing (absent or unreadable).
std::optional<StudyStatus> read_status(const std::filesystem::path& file);

/// A study's outcome from its status, or from how its process ended when it wrote none.
StudyOutcome outcome_from_status(const std::string& id, const std::optional<StudyStatus>& status, int process_code,
                                 const std::string& ended_how);

/// The progress line "studies: N done, R running, F failed of T".
class Tally {
 public:
  Tally(Progress& p, std::size_t total) : progress_(p), total_(total) {}
  void show(std::size_t done, std::size_t running, std::size_t failed);

 private:
  Progress& progress_;
  std::size_t total_;
};

/// Submits studies `todo` as one Slurm job array (recorded in cohort/slurm_arrays.json until every
/// task is collected) and waits for them. Throws SchedulerError (exit 81) when sbatch refuses, or
/// when the controller stays silent for options.scheduler_wait_s (the array goes on running; a rerun
/// collects it).
std::vector<StudyOutcome> run_slurm(const CohortPlan& plan, const std::vector<std::size_t>& todo,
                                    const CohortOptions& options, Progress& progress, std::vector<std::string>& jobs);

/// Job arrays an earlier run submitted and did not collect (it stopped, or the controller went
/// silent): waits for their tasks that are still queued or running, so that no study runs twice.
/// Returns (study index, outcome) for each task waited for; forgets arrays with nothing left.
std::vector<std::pair<std::size_t, StudyOutcome>> collect_earlier_slurm_arrays(const CohortPlan& plan,
                                                                               const CohortOptions& options,
                                                                               Progress& progress,
                                                                               std::vector<std::string>& jobs);

}  // namespace organsmith::cohort_detail
