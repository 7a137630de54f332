#pragma once
// Subcommands contributed by the stage modules' command files (cmd_*.cpp). Each registers its
// options on the application and returns what to run when the user chose it; main() dispatches
// and turns organsmith::Error into the documented exit codes.

#include <CLI/CLI.hpp>

#include <functional>
#include <vector>

namespace organsmith {

struct Command {
  CLI::App* sub = nullptr;       ///< the registered subcommand
  std::function<int()> run;      ///< returns the exit code; may throw organsmith::Error
};

/// `calibrate`, `uncertainty`, `materials` (physics; pipeline/cli/cmd_physics.cpp).
std::vector<Command> physics_commands(CLI::App& app);
/// `segment` (segmentation; pipeline/cli/cmd_segment.cpp).
std::vector<Command> segmentation_commands(CLI::App& app);
/// `mesh` (meshing; pipeline/cli/cmd_mesh.cpp).
std::vector<Command> meshing_commands(CLI::App& app);
/// `snapshot`, `preview` (viewer; pipeline/cli/cmd_viewer.cpp).
std::vector<Command> viewer_commands(CLI::App& app);
/// `degrade` (physics, clip degradation; pipeline/cli/cmd_degrade.cpp).
std::vector<Command> degradation_commands(CLI::App& app);
/// `guide`, `haptics` (physics, guidance paths and the force loop; pipeline/cli/cmd_haptics.cpp).
std::vector<Command> haptics_commands(CLI::App& app);
/// `simulate` (CalculiX runs of the organs' load cases; pipeline/cli/cmd_simulate.cpp).
std::vector<Command> simulate_commands(CLI::App& app);
/// `cohort` (many studies, local or Slurm; pipeline/cli/cmd_cohort.cpp).
std::vector<Command> cohort_commands(CLI::App& app);
/// `pull` (a study from a PACS into a cache; pipeline/cli/cmd_pull.cpp).
std::vector<Command> pacs_commands(CLI::App& app);

}  // namespace organsmith
