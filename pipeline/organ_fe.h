#pragma once
// The organ's real-time finite-element model, built from the solver input the mesh stage wrote
// (meshes/<organ>/<organ>.inp): the same nodes, elements, regions' laws, fixed set and probe as
// the CalculiX run, on the quadratic tetrahedra or on their corner nodes (linear tetrahedra:
// about a sixth of the nodes, for the haptic rate). And `haptics --indent`: the simulate stage's
// indentation driven quasi-statically through that model, set against the solver's curve.

#include "core/progress.h"
#include "meshing/solver_model.h"
#include "physics/tissue/tissue_model.h"

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include <filesystem>
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
nlohmann::json realtime_press(physics::TissueModel& model, const OrganFe& fe, double depth_mm, Progress& progress);

/// Throws InputError naming the INP when it is missing, has no indentation probe where one is
/// asked for, or a region has no law.
OrganFe organ_fe(const std::filesystem::path& out_dir, const std::string& organ, const OrganFeOptions& options);

struct IndentOptions {
  OrganFeOptions fe;
  double max_step_mm = 0.15;  ///< probe travel per quasi-static increment
};

/// The indentation through the real-time model: `curve` at the simulate stage's depths (its
/// simulation/<organ>.json when present, else 0.15 mm steps to the file's depth), the solver's
/// curve beside it with the relative difference at each depth, and the model's size and solve
/// times. Throws SimulationError (71) when an increment does not converge.
nlohmann::json haptics_indent(const std::filesystem::path& out_dir, const std::string& organ, const IndentOptions& options,
                              Progress& progress);

}  // namespace organsmith
