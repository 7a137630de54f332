// One study of a cohort, in its own process: the task that the local pool and every Slurm array
// task run (`organsmith cohort-study DIR INDEX`).
#include "core/errors.h"
#include "core/file_io.h"
#include "pipeline/case/case_file.h"
#include "pipeline/cohort/cohort.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/run/runner.h"
#include "pipeline/run/terminal_progress.h"

#include <spdlog/spdlog.h>

#include <chrono>

namespace fs = std::filesystem;

namespace organsmith {

int run_cohort_study(const CohortPlan& plan, std::size_t index) {
  const CohortStudy& s = plan.studies.at(index);
  const CohortLayout layout{plan.out_dir};
  StudyStatus status;
  status.id = s.id;
  status.fingerprint = s.fingerprint;
  const auto t0 = std::chrono::steady_clock::now();
  spdlog::info("cohort study '{}' (row {} of the cohort file)", s.id, s.line);
  try {
    CaseFile c = parse_case(s.case_toml, s.case_origin);
    c.out_dir = layout.study(s.id);
    TerminalProgress progress(false);
    RunOptions options;
    run_case(c, options, progress);
    progress.finish();
    status.exit_code = 0;
  } catch (const Error& e) {
    status.exit_code = int(e.code());
    status.message = redact_study_text(s, e.what());
    spdlog::error("{}", status.message);
  } catch (const std::exception& e) {
    status.exit_code = int(ExitCode::internal);
    status.message = redact_study_text(s, std::string("internal error: ") + e.what());
    spdlog::error("{}", status.message);
  }
  status.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fs::create_directories(layout.status(s.id).parent_path());
  write_file_atomic(layout.status(s.id), to_json(status).dump(2) + "\n");
  spdlog::info("cohort study '{}': exit {} after {:.1f} s", s.id, status.exit_code, status.seconds);
  return status.exit_code;
}

}  // namespace organsmith
