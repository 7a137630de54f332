// `organsmith simulate OUT_DIR`: the simulate stage of a run's directory (see pipeline/stages/simulate.h).

#include "pipeline/case/case_file.h"
#include "pipeline/cli/commands.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/run/runner.h"
#include "pipeline/run/terminal_progress.h"

#include <nlohmann/json.hpp>

#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>

namespace organsmith {
namespace fs = std::filesystem;

namespace {

struct SimulateArgs {
  std::string out;
  std::vector<std::string> organs;
  std::string solver = "ccx";
  int threads = -1;
  double timeout_s = -1;
  bool band = false;
  bool force = false;
};

int cmd_simulate(const SimulateArgs& a) {
  const fs::path out = fs::absolute(a.out);
  std::error_code ec;
  if (!fs::is_directory(out, ec))
    throw InputError(ExitCode::input_not_found, "no such output directory", out, "run `organsmith run --out " + a.out + "` first");
  std::optional<CaseFile> c = case_of_run(out);
  if (!c)
    throw InputError(ExitCode::input_not_found, "this directory holds no run (no manifest with a case)", out,
                     "simulate works on the output of `organsmith run` (or segment then mesh)");
  // The solver executable: `ccx` on PATH, or the CalculiX binary named here (passed to the stage
  // as ORGANSMITH_CCX, which a user may also set).
  if (a.solver != "ccx") setenv("ORGANSMITH_CCX", a.solver.c_str(), 1);
  if (!a.organs.empty()) c->stages.simulate.organs = a.organs;
  if (a.threads >= 0) c->stages.simulate.threads = a.threads;
  if (a.timeout_s >= 0) c->stages.simulate.timeout_s = a.timeout_s;
  if (a.band) c->stages.simulate.band = true;
  RunOptions ro;
  ro.from = "simulate";
  ro.force = a.force;
  ro.until = "simulate";
  TerminalProgress progress;
  const RunSummary summary = run_case(*c, ro, progress);
  progress.finish();
  const OutputLayout layout{out};
  for (const auto& o : c->organs) {
    const fs::path j = layout.simulation(o.name, "json");
    std::ifstream in(j);
    if (!in) continue;
    const nlohmann::json r = nlohmann::json::parse(in);
    std::cout << o.name << ": converged in " << r["increments"] << " increments, " << r["max_displacement_mm"]
              << " mm largest displacement, " << r["max_von_mises_Pa"] << " Pa largest von Mises stress, reaction balance "
              << r["reaction_balance_error"] << "\n";
    if (r.contains("band") && r["band"].contains("max_displacement_mm"))
      std::cout << "  material band P5–P95: largest displacement " << r["band"]["max_displacement_mm"][0] << "–"
                << r["band"]["max_displacement_mm"][1] << " mm, lumen volume change "
                << r["band"]["lumen_volume_change_mm3"][0] << "–" << r["band"]["lumen_volume_change_mm3"][1] << " mm³\n";
    else if (r.contains("band"))
      std::cout << "  material band: not every variant converged (see band.variants)\n";
    std::cout << "  " << j.string() << "\n";
  }
  (void)summary;
  return 0;
}

}  // namespace

std::vector<Command> simulate_commands(CLI::App& app) {
  auto a = std::make_shared<SimulateArgs>();
  auto* cmd = app.add_subcommand(
      "simulate",
      "Run each organ's load case (meshes/<organ>/<organ>.inp: gallbladder — liver bed fixed, a 5 mm\n"
      "flat probe pressed into the free wall opposite it, the force–depth curve recorded; trachea —\n"
      "both cut ends fixed, airway pressure in the lumen) in CalculiX (Debian package calculix-ccx)\n"
      "and write simulation/<organ>.vtu (displacement, von Mises stress) and simulation/<organ>.json\n"
      "(convergence, increments, solver time, reaction balance, largest displacement and stress, the\n"
      "indentation curve or the lumen volume change). `haptics OUT_DIR --indent ORGAN` presses the\n"
      "haptic model the same way and compares. Exit 70: no solver; 71: no converged answer.");
  cmd->add_option("OUT_DIR", a->out, "output directory of `organsmith run`")->required();
  cmd->add_option("--organ", a->organs, "organ to simulate (repeatable; default: every organ with a load case)");
  cmd->add_option("--solver", a->solver, "CalculiX executable (default: ccx on PATH, or $ORGANSMITH_CCX)");
  cmd->add_option("--threads", a->threads, "solver threads (default: the case's, 0 = every core)")->check(CLI::Range(0, 1024));
  cmd->add_flag("--force", a->force, "redo the stage even when it is unchanged since the last run");
  cmd->add_flag("--band", a->band,
                "also run the material band's P5/P50/P95 variants (written by `mesh DIR --material-band` or\n"
                "[stages.mesh] material_band) and report the largest displacement as a band");
  cmd->add_option("--timeout-s", a->timeout_s, "stop a solver run after this many seconds (default: none)")
      ->check(CLI::Range(0.0, 1.0e6));
  return {{cmd, [a] { return cmd_simulate(*a); }}};
}

}  // namespace organsmith
