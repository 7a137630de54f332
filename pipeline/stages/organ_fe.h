#pragma once
// The organ's real-time finite-element model, built from the solver input the mesh stage wrote
// (meshes/<organ>/<organ>.inp): the same nodes, elements, regions' laws, fixed set and probe as
// the CalculiX run, on the quadratic tetrahedra or on their corner nodes (linear tetrahedra:
// about a sixth of the nodes, for the haptic rate). And `haptics --indent`: the simulate stage's
// indentation driven quasi-statically through that model, set against the solver's curve.

#include "core/progress.h"
#include "meshing/solver_model.h"
#include "physics/haptics/haptic_loop.h"
#include "physics/tissue/realtime_tissue.h"
#include "physics/tissue/tissue_model.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

struct OrganFe {
  std::string organ;
  std::filesystem::path inp;
  physics::TissueMesh mesh;
  std::vector<std::int32_t> fixed_nodes, probe_nodes;  ///< ids in `mesh`
  std::vector<std::int32_t> surface_triangles;        ///< outer surface, 3 ids in `mesh` per face (outward)
  std::optional<SolverProbe> probe;                   ///< the indentation probe (wall_body organs)
  double probe_depth_mm = 0.0;                        ///< the step's depth
  std::vector<std::string> region_names;              ///< per law index
  std::map<std::string, double> stretch_max;          ///< each region's calibrated range (materials.json)
};

struct OrganFeOptions {
  bool quadratic = false;  ///< 10-node tetrahedra as in the solver file; false = corner nodes only
  /// Move the probe to the free surface point nearest this (LPS mm); empty = the file's probe.
  std::optional<Eigen::Vector3d> probe_lps_mm;
};

/// The real-time model pressed through its own threads (RealtimeTissue at 60 Hz, a 1 kHz force
/// loop on this thread): a tool sphere from 1 mm off the probe point along the probe's direction
/// to `depth_mm`, held, withdrawn, one second at rest. The `fe` timing figures and the rest check.
nlohmann::json realtime_press(physics::TissueModel& model, const OrganFe& fe, double depth_mm, double speed_mm_per_s,
                              Progress& progress);

/// Throws InputError naming the INP when it is missing, has no indentation probe where one is
/// asked for, or a region has no law.
OrganFe organ_fe(const std::filesystem::path& out_dir, const std::string& organ, const OrganFeOptions& options);

/// The organ's real-time model for a haptic loop (`preview`, `haptics --trajectory`): the solver
/// file's model (its 10-node tetrahedra, or their corner nodes with `quadratic` false), its
/// threads (not started) and the loop's reaction source (the tool sent to the model, its contact
/// force read back; both lock-free).
struct RealtimeOrgan final : physics::ReactionSource {
  OrganFe fe;
  std::unique_ptr<physics::TissueModel> model;
  std::unique_ptr<physics::RealtimeTissue> tissue;
  Eigen::Vector3d reaction_N(const Eigen::Vector3d& tip) noexcept override {
    tissue->set_tool(tip);
    return tissue->tool_force_N(tip);
  }
  /// nodes, tets, update_ms_p50/p99, update_hz, updates, updates_refactorising.
  nlohmann::json figures() const;
};
std::unique_ptr<RealtimeOrgan> realtime_organ(const std::filesystem::path& out_dir, const std::string& organ, double tool_radius_mm,
                                              bool quadratic);
/// `--fe ORGAN` of `preview` and `haptics --trajectory`: that organ's model (errors are the
/// command's); empty (the default): the gallbladder's where the mesh stage wrote its solver file
/// and a model can be built from it (else null, with a warning naming why); "none": null.
std::unique_ptr<RealtimeOrgan> fe_for_haptics(const std::filesystem::path& out_dir, const std::string& fe_flag,
                                              double tool_radius_mm, bool quadratic);

struct IndentOptions {
  OrganFeOptions fe;
  double max_step_mm = 0.15;  ///< probe travel per quasi-static increment
  std::filesystem::path picture_png;  ///< the organ at the deepest indentation, stress-coloured (none: empty)
  bool realtime_press = true;         ///< also press the real-time model through its threads (the `fe` figures)
  /// … at this speed: slow enough for the 10-node model's equilibria to keep up on two cores
  /// (quasi-static; TISSUE.md has the felt curve's error against the speed).
  double press_speed_mm_per_s = 0.5;
  int picture_width_px = 1024, picture_height_px = 768;
};

/// The indentation through the real-time model: `curve` at the simulate stage's depths (its
/// simulation/<organ>.json when present, else 0.15 mm steps to the file's depth), the solver's
/// curve beside it with the relative difference at each depth, and the model's size and solve
/// times. Throws SimulationError (71) when an increment does not converge.
nlohmann::json haptics_indent(const std::filesystem::path& out_dir, const std::string& organ, const IndentOptions& options,
                              Progress& progress);

}  // namespace organsmith
