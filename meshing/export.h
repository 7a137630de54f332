#pragma once
// Writers for organ meshes in the formats simulators and viewers load unedited. Every file is
// written atomically (a temporary file in the same directory, then a rename), so a failed
// export never leaves a partial file. Coordinates are LPS mm unless `ras` is set (then x and y
// are negated: a rotation, so orientation and volumes are unchanged).

#include "core/geometry.h"
#include "core/material.h"
#include "meshing/mesh.h"
#include "meshing/solver_model.h"

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace organsmith {

/// Every format `export_meshes` knows, in the order files are written.
/// Surfaces: stl (binary), obj, ply (binary little-endian), vtp. Volumes: vtu, msh (Gmsh 4.1),
/// msh22 (Gmsh 2.2), inp (Abaqus), feb (FEBio 4.0).
std::vector<std::string> all_mesh_formats();

struct ExportOptions {
  std::vector<std::string> formats = all_mesh_formats();
  bool ras = false;  ///< write RAS instead of LPS coordinates
  /// Quadratic tetrahedra (C3D10 / tet10 / VTK 24 / Gmsh 11) in every volume format; false
  /// writes linear ones (C3D4 / tet4).
  bool quadratic = true;
  /// Solver material per tet region name ("gallbladder_wall", …), fitted to the calibrated law
  /// (physics/materials/solver_fit.h); stresses in MPa in the files (meshes are in mm). A region
  /// without an entry gets a documented placeholder and a warning.
  std::map<std::string, SolverMaterial> materials;
  /// Material band: variant name ("p05", "p50", "p95") → solver material per region. Each variant
  /// gets its own INP, `<organ>/band/<organ>.<variant>.inp`, the same model and load step with
  /// that variant's materials (regions it does not name keep `materials`). Empty: none.
  std::map<std::string, std::map<std::string, SolverMaterial>> material_band;
  /// Load case per organ name; organs without an entry get default_scenario(spec).
  std::map<std::string, SolverScenario> scenarios;
  /// How boundary surfaces are found (liver bed direction, liver label distance).
  SolverModelOptions boundaries;
};

/// Writes every organ into `dir/<organ>/`: one file per surface and format
/// (`<surface>.stl`, …), one per volume format (`<organ>.vtu`, `<organ>.msh`,
/// `<organ>.v22.msh`, `<organ>.inp`, `<organ>.feb`, and `band/<organ>.<variant>.inp` with a
/// material band; the solver files with named sets,
/// surfaces and the organ's load step) and `quality.json` with every quality figure. Returns the files written, relative to `dir`, in a fixed order; `warnings`
/// receives what the user should know (placeholder materials). Throws OutputError.
std::vector<std::filesystem::path> export_meshes(const OrganMeshes& meshes, const std::filesystem::path& dir,
                                                 const ExportOptions& options, std::vector<std::string>* warnings = nullptr);

/// Single-file writers (atomic). `region_names` maps tet region ids to names.
void write_stl(const SurfaceMesh& m, const std::filesystem::path& path, bool ras = false);
void write_obj(const SurfaceMesh& m, const std::filesystem::path& path, bool ras = false);
void write_ply(const SurfaceMesh& m, const std::filesystem::path& path, bool ras = false);
void write_vtp(const SurfaceMesh& m, const std::filesystem::path& path, bool ras = false);
/// A named per-node array for write_vtu (`components` values per node, node order).
struct PointField {
  std::string name;
  int components = 1;
  std::vector<double> values;
};

/// Volume writers of one organ's solver model. `scenario` adds the load step (INP, FEB);
/// an empty fixed_surface writes the model without one.
void write_vtu(const SolverModel& m, const std::filesystem::path& path, bool ras = false,
               const std::vector<PointField>& point_fields = {});
void write_msh41(const SolverModel& m, const std::filesystem::path& path, bool ras = false);
void write_msh22(const SolverModel& m, const std::filesystem::path& path, bool ras = false);
void write_inp(const SolverModel& m, const std::map<std::string, SolverMaterial>& materials,
               const SolverScenario& scenario, const std::filesystem::path& path, bool ras = false,
               std::vector<std::string>* warnings = nullptr);
void write_feb(const SolverModel& m, const std::map<std::string, SolverMaterial>& materials,
               const SolverScenario& scenario, const std::filesystem::path& path, bool ras = false);

/// Reads a binary STL back (for round-trip checks): triangles with merged vertices.
SurfaceMesh read_stl(const std::filesystem::path& path);

/// quality.json content for one organ.
std::string quality_json(const OrganMesh& organ);

}  // namespace organsmith
