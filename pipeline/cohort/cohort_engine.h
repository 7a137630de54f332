#pragma once
// Running a cohort's studies: a local process pool or one Slurm job array, with retries, reuse of
// completed studies, and the summary at the end.

#include "core/progress.h"
#include "pipeline/cohort/cohort.h"

#include <string>
#include <vector>

namespace organsmith {

struct CohortOptions {
  std::string engine = "local";   ///< "local" (a process pool here) or "slurm" (sbatch job array)
  int cpus_per_study = 0;         ///< threads of each study; 0 = cores ÷ studies, at least 1
  double memory_mb_per_study = 0; ///< 0 = measured: the largest peak RSS of this cohort's studies so far × 1.25
                                  ///< (2048 MB before any study has run)
  int jobs = 0;                   ///< studies at a time (local: 0 = by cores and memory; slurm: the array's %K, 0 = no limit)
  int retries = 1;                ///< reruns of a study that was killed, timed out or crashed (not of bad inputs)
  bool force = false;             ///< rerun studies that completed with the same fingerprint
  double time_limit_min = 0;      ///< slurm --time per study; 0 = 3 × the slowest study so far (at least 30 min), else 120
  std::string partition, account, qos;
  std::vector<std::string> sbatch_lines;  ///< further "#SBATCH …" directives, as given
  bool submit = true;             ///< slurm: false = write the script and the plan only
  double poll_s = 1.0;            ///< how often the engine looks at its studies
  double scheduler_wait_s = 600;  ///< slurm: how long the controller may stay silent before the run stops (exit 81)
};

struct StudyOutcome {
  std::string id;
  std::string state;       ///< "done", "reused" (completed before, same fingerprint), "failed", "not submitted"
  int exit_code = -1;      ///< the study's exit code; 128 + signal when killed; -1 when unknown
  std::string message;     ///< the study's last error (no input path), or what the scheduler said
  int attempts = 0;
  double seconds = 0.0;
};

struct CohortResult {
  std::vector<StudyOutcome> studies;  ///< in the cohort file's order
  std::vector<std::string> slurm_jobs;
  double seconds = 0.0;
  int failed() const;
};

/// Runs every study of `plan` into plan.out_dir (see CohortLayout), then writes the summary
/// (cohort.csv, cohort.json, cohort.png). A failing study never stops the others. Throws
/// OutputError for an unusable output directory, SchedulerError when Slurm refuses or cannot
/// be reached, Cancelled on Ctrl-C (the studies running are stopped first).
CohortResult run_cohort(const CohortPlan& plan, const CohortOptions& options, Progress& progress);

/// The sbatch script of the cohort's job array (what `--engine slurm` submits and keeps in
/// cohort/cohort.sbatch for a resubmission by hand). Holds no input path and no patient data.
std::string slurm_script(const CohortPlan& plan, const CohortOptions& options, int cpus, double memory_mb,
                         double time_limit_min);

}  // namespace organsmith
