#pragma once
// A cohort's summary: cohort.csv and cohort.json (one row per study: state, exit code, stage
// times, peak memory, organ volumes, mesh quality, Dice against a given reference, simulation
// figures) and cohort.png (every study's 3-D view with its id and state). No input path and no
// patient data appear in any of them.

#include "core/progress.h"
#include "pipeline/cohort/cohort.h"
#include "pipeline/cohort/cohort_engine.h"

#include <filesystem>

namespace organsmith {

/// The summary as JSON, read from each study's output folder under plan.out_dir.
nlohmann::json cohort_summary_json(const CohortPlan& plan, const CohortResult& result);

/// Writes cohort.csv, cohort.json and cohort.png into `dir` (laid out as CohortLayout).
void write_cohort_summary(const CohortPlan& plan, const CohortResult& result, const std::filesystem::path& dir,
                          Progress& progress);

}  // namespace organsmith
