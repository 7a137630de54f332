#pragma once
// The simulate stage: every organ's exported load case (meshes/<organ>/<organ>.inp) in CalculiX,
// into simulation/<organ>.vtu, .json and pictures; the solver's log and tables stay in
// simulation/<organ>_solver/. Run by `organsmith run` and `organsmith simulate DIR` (through the
// runner).

#include "core/progress.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/case/stage_options.h"

#include <filesystem>
#include <string>
#include <vector>

namespace organsmith {

struct SimulateStageInputs {
  std::filesystem::path out_dir;             ///< the run's directory: its meshes/ and earlier results
  const OrganRegistry* registry = nullptr;   ///< required: mesh models, materials, the thesis' curve
  std::vector<std::string> organs;           ///< the case's organs, in order
  int picture_width_px = 1024, picture_height_px = 768;
};

/// Simulates every organ of `in.organs` with a wall and a load step (options.organs: only those;
/// the others' earlier results are carried into `staging`). A solver failure throws
/// SimulationError naming the solver's log, kept under `in.out_dir`.
void simulate_stage(const SimulateStageInputs& in, const SimulateStageOptions& options,
                    const std::filesystem::path& staging, Progress& progress);

}  // namespace organsmith
