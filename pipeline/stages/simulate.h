#pragma once
// simulate: runs an organ's exported load case (meshes/<organ>/<organ>.inp) in CalculiX and reads
// the answer back: converged or not, increments, solver time, the reaction at the fixed set
// against the resultant of the applied pressure (computed from the loaded faces in their deformed
// place, not read from the solver), largest displacement and stress, lumen volume change. The
// INP is read by its matching reader (read_solver_inp); the solver's .frd and .dat by the readers
// below.

#include "core/errors.h"
#include "core/progress.h"
#include "meshing/solver_model.h"
#include "physics/tissue/ogden_solid.h"

#include <array>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// The solver could not run or did not converge (exit 70 / 71); the message quotes the solver.
class SimulationError : public Error {
 public:
  SimulationError(ExitCode code, std::string message, std::filesystem::path path = {}, std::string hint = {})
      : Error(code, std::move(message), std::move(path), std::move(hint)) {}
};

/// An INP written by write_inp, read back: the model, its load case and the fixed node set.
struct SolverInput {
  SolverModel model;
  std::string fixed_node_set;     ///< name of the *BOUNDARY set of the load case
  std::string pressure_surface;   ///< the *DSLOAD surface
  double pressure_MPa = 0.0;
  std::vector<std::string> inactive_regions;
  bool ras = false;               ///< coordinates in the file are RAS
  /// Indentation (instead of a pressure): the probe's node set, where it touches, its direction
  /// (LPS) and the depth it is pressed to at the end of the step.
  std::string probe_node_set;
  SolverProbe probe;
  double probe_depth_mm = 0.0;
  /// Each region's law as the file states it (*HYPERELASTIC OGDEN, MOONEY-RIVLIN or NEO HOOKE,
  /// through *SOLID SECTION), as an Ogden solid in N/mm²; Mooney–Rivlin is the pair α = 2, −2.
  std::map<std::string, physics::OgdenSolid> region_laws;
  bool indentation() const { return !probe_node_set.empty(); }
};
/// Reads an INP that organsmith wrote. InputError naming the file and line on anything else.
SolverInput read_solver_inp(const std::filesystem::path& inp);
/// True when the INP has a load step (organs whose surfaces could not be found have none).
bool has_load_case(const SolverInput& in);

/// Last converged result of a CalculiX .frd: node displacements (mm) and nodal stresses (MPa,
/// xx yy zz xy yz zx), indexed by 0-based node id (rows of zeros for nodes without a value).
struct FrdResult {
  std::vector<std::array<double, 3>> displacement_mm;
  std::vector<std::array<double, 6>> stress_MPa;
  double time = 0.0;
};
FrdResult read_frd(const std::filesystem::path& frd, std::size_t node_count);

/// Von Mises stress of a stress tensor (xx yy zz xy yz zx), same unit.
double von_mises(const std::array<double, 6>& stress);

struct SimulateOptions {
  std::string solver = "ccx";  ///< executable, looked up on PATH
  int threads = 0;             ///< OpenMP threads of the solver; 0 = every core
  double timeout_s = 0.0;      ///< 0 = none
  /// Top of each region's calibrated stretch range (region name → stretch > 1). The indentation
  /// curve ends where the first region's 99th-percentile principal stretch reaches it; a pressure
  /// step reports the pressure at which it does. Regions not named are not checked.
  std::map<std::string, double> calibrated_stretch_max;
};

/// One converged increment of a step: its time (the load fraction), the displacement of every
/// node (mm, LPS) and the sum of RF over named node sets (N).
struct SolverIncrement {
  double time = 0.0;
  std::vector<std::array<double, 3>> displacement_mm;
};
/// Every converged increment's displacement in a CalculiX .frd (the file's frame).
std::vector<SolverIncrement> read_frd_increments(const std::filesystem::path& frd, std::size_t node_count);
/// Sum of RF over `set` at every increment printed in a .dat (time → force, N).
std::vector<std::pair<double, std::array<double, 3>>> read_dat_series(const std::filesystem::path& dat,
                                                                      const std::string& set);

/// Per region (active elements only): the largest and the 99th-percentile principal stretch of
/// the elements under `displacement_mm` (from the corners: each element's mean deformation).
std::map<std::string, std::pair<double, double>> region_stretches(const SolverInput& in,
                                                                  const std::vector<std::array<double, 3>>& displacement_mm);

/// The thesis' indentation test on the organ: force against depth, to the depth where the first
/// region reaches the top of its calibrated range (or the step's depth when none does).
struct IndentationResult {
  SolverProbe probe;                      ///< point and direction in LPS
  double step_depth_mm = 0.0;             ///< the depth the step presses to
  std::vector<std::array<double, 2>> curve;  ///< [depth mm, force N], from 0 to the range limit
  double range_depth_mm = 0.0;            ///< where the curve ends
  std::string range_region;               ///< the region that reached its range first ("" = none did)
  double range_stretch = 0.0;             ///< that region's range (its calibrated stretch_max)
  double stiffness_N_per_mm_at_1mm = 0.0; ///< dF/dδ at 1 mm (NaN when the curve ends before 1 mm)
  double fixed_reaction_N = 0.0;          ///< the fixed set's reaction along the probe at the deepest converged point
  double probe_force_N = 0.0;             ///< the probe's force at that point
  double balance_error = 0.0;             ///< |probe + fixed| / |probe| there
  /// The thesis' reading of its own test (§5.1.5): the organ law's uniaxial nominal stress at
  /// strain depth / organ thickness, times the probe's area ([depth mm, force N]; set by the caller).
  std::vector<std::array<double, 2>> thesis_curve;
  std::string thesis_source;
  nlohmann::json to_json() const;
};

/// The pressure at which a pressure step's first region reaches its range (interpolated between
/// increments), and which region; pressure 0 when none does.
struct PressureRange {
  double in_range_pressure_kPa = 0.0;
  std::string region;
};

/// The indentation figures from a step's increments, the probe's and the fixed set's RF totals
/// (read_dat_series) and each region's range.
IndentationResult evaluate_indentation(const SolverInput& in, const std::vector<SolverIncrement>& increments,
                                       const std::vector<std::pair<double, std::array<double, 3>>>& probe_rf,
                                       const std::vector<std::pair<double, std::array<double, 3>>>& fixed_rf,
                                       const std::map<std::string, double>& calibrated_stretch_max);
/// While an indentation step runs: the load fraction at which the first region's 99th-percentile
/// stretch reached its range, once the solver's .frd and .dat both hold an increment at or
/// beyond it (the curve is then complete and the rest of the step is past the law's data);
/// −1 before.
double indentation_range_time(const SolverInput& in, const std::filesystem::path& frd, const std::filesystem::path& dat,
                              const std::map<std::string, double>& calibrated_stretch_max);
PressureRange evaluate_pressure_range(const SolverInput& in, const std::vector<SolverIncrement>& increments,
                                      const std::map<std::string, double>& calibrated_stretch_max);

struct SimulationResult {
  std::string organ;
  bool converged = false;
  int increments = 0;            ///< converged increments
  int cutbacks = 0;              ///< attempts the solver cut back
  double solver_seconds = 0.0;
  double load_factor = 0.0;      ///< fraction of the load reached (1 when converged)
  std::array<double, 3> reaction_N{0, 0, 0};          ///< sum of RF over the fixed set
  std::array<double, 3> applied_resultant_N{0, 0, 0}; ///< ∫ p n da over the loaded faces, deformed
  double load_magnitude_N = 0.0;  ///< p Σ |area| of the loaded faces (the scale of the balance)
  double balance_error = 0.0;     ///< |reaction − applied| / load_magnitude
  double max_displacement_mm = 0.0;
  double max_von_mises_Pa = 0.0;
  double lumen_volume_mm3 = 0.0, lumen_volume_change_mm3 = 0.0;
  std::string solver_message;     ///< the solver's own words when it failed
  /// Largest principal stretch of the active elements, per region (from the corner
  /// displacements: the element's mean deformation): the largest and the 99th percentile. A law
  /// is only known up to its calibrated stretch (`calibrated_stretch_max`, set by the caller from
  /// the region's material); beyond it the answer is the fitted solid's extrapolation.
  struct RegionStretch {
    double max = 1.0, p99 = 1.0, calibrated_max = 0.0;  ///< calibrated_max 0 = unknown
  };
  std::map<std::string, RegionStretch> principal_stretch;
  /// The material band's runs (see band_summary), null when none were run.
  nlohmann::json band;
  /// Indentation steps: the curve and its figures.
  std::optional<IndentationResult> indentation;
  /// Pressure steps: the step's pressure (kPa) and the largest within every region's range.
  double pressure_kPa = 0.0;
  std::optional<PressureRange> pressure_range;
  nlohmann::json to_json() const;
};

/// The model, the solver's answer and the figures drawn from both.
struct Simulation {
  SolverInput input;
  FrdResult frd;
  SimulationResult result;
};

/// The material band of one organ: each variant's run ("p05" → its result; a variant whose run
/// failed has converged = false and the solver's message), and the band of the largest
/// displacement and the lumen volume change over the converged variants.
nlohmann::json band_summary(const std::map<std::string, SimulationResult>& variants);

/// Runs `inp` in CalculiX inside `work_dir` (created; the solver's files stay there) and reads
/// the result. Throws SimulationError: exit 70 when the solver is not installed, 71 when it
/// stops without converging (with its message and the load fraction reached).
Simulation simulate_inp(const std::filesystem::path& inp, const std::filesystem::path& work_dir,
                        const SimulateOptions& options, Progress& progress);
/// The same with the INP already read (`input` = read_solver_inp(inp)): the file is parsed once.
Simulation simulate_inp(const std::filesystem::path& inp, SolverInput input, const std::filesystem::path& work_dir,
                        const SimulateOptions& options, Progress& progress);

/// The figures of a result against its model (balance, displacement, stress, lumen volume).
void evaluate_simulation(const SolverInput& in, const FrdResult& frd, SimulationResult& r);

/// Writes the simulation result of one organ: `<organ>.vtu` (undeformed nodes with displacement
/// and von Mises stress per node, region per element) and `<organ>.json`.
void write_simulation_files(const SolverInput& in, const FrdResult& frd, const SimulationResult& r,
                            const std::filesystem::path& dir);

}  // namespace organsmith
