#pragma once
// The organ registry: everything organsmith knows about an organ, in one place
// (data/organs.toml, embedded; a case may add or change organs with its own registry file).
// Every stage asks the registry; no stage knows organ names or label values of its own.

#include "core/material.h"
#include "meshing/mesh.h"
#include "physics/materials/solver_fit.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace organsmith {

/// How an organ is meshed.
enum class OrganMeshModel {
  none,       ///< context only (drawn around the modelled organs, never meshed)
  wall_body,  ///< a wall of `wall_mm` over a body (regions <name>_wall, <name>_body)
  tube,       ///< a tube wall of `wall_mm` around an air lumen (region <name>_wall)
  solid,      ///< one solid body (region <name>)
};

struct OrganInfo {
  std::string name;
  std::uint8_t label = 0;            ///< value in label maps
  OrganMeshModel mesh = OrganMeshModel::none;
  double wall_mm = 0.0;              ///< wall thickness for wall_body and tube, mm
  TubeRings rings;                   ///< tube: cartilage rings and membrane (pitch 0 = one wall region)
  std::string load_case;             ///< default load case: "indentation", "pressure" or "" (none)
  double pressure_kPa = 0.0;         ///< lumen pressure of the pressure load case, kPa
  double probe_diameter_mm = 5.0;    ///< indentation probe diameter, mm
  std::map<std::string, std::string> materials;  ///< tet region → material preset id (data/materials.toml)
  std::string haptic_surface;        ///< surface the tool touches (see surfaces()); empty = not touched
  std::string haptic_region;         ///< region whose calibrated law the tool feels
  double haptic_max_strain = 0.6;    ///< strain up to which the law is tabulated for the force loop
  std::array<double, 3> colour_rgb{0.6, 0.6, 0.62};  ///< display colour, components in [0, 1]
  double opacity = 1.0;              ///< display opacity of context organs (modelled organs: opaque body)
  bool segmented = false;            ///< has a segmentation preset: the segment stage finds it
  bool needs_seed = false;           ///< its segmentation starts from a seed inside it
  /// Guidance paths the guide stage makes on it, by kind: "centerline" and "incision" (a tube),
  /// "dissection" (a wall_body: the rim of its bed); each is written as <name>_<kind>.
  std::vector<std::string> paths;
  /// wall_body: the organ it lies against (its bed: the fixed set of its load case and the
  /// dissection's side); "" = none (the bed then faces that organ's usual direction).
  std::string bed_organ;

  /// Tet region names of the mesh model ({} for none).
  std::vector<std::string> regions() const;
  /// Surface names the mesh stage writes for it, outermost first ({} for none).
  std::vector<std::string> surfaces() const;
  /// The surface drawn translucent over the others (the wall of wall_body and tube), or "".
  std::string wall_surface() const;
};

struct OrganRegistry {
  std::vector<OrganInfo> organs;  ///< in file order

  const OrganInfo* find(std::string_view name) const;
  const OrganInfo* find_label(std::uint8_t label) const;
  /// The organ, or InputError naming `origin` and listing the known organs.
  const OrganInfo& at(std::string_view name, const std::filesystem::path& origin = {}) const;
  std::vector<std::string> names() const;
  /// Names of the organs a case may model (mesh model other than none).
  std::vector<std::string> modelled() const;
  /// Every guidance path the registry's organs have (<organ>_<kind>), in registry order.
  std::vector<std::string> path_names() const;
  /// The same in the order a tool follows one when none is named: incisions (a cut along the
  /// organ), then dissections (the rim of a bed), then centrelines; registry order within a kind.
  std::vector<std::string> preferred_path_names() const;
};

/// The embedded data/organs.toml.
std::string_view builtin_registry_toml();

/// The embedded registry.
const OrganRegistry& builtin_organ_registry();

/// Parses registry TOML over `base`: a table per organ; an organ of `base` keeps every key the
/// text does not give. Unknown keys, wrong types, values out of range, duplicate labels, material
/// regions that do not match the mesh model or presets that do not exist throw CaseFileError
/// (exit 20) naming `origin`, the organ and the key.
OrganRegistry parse_organ_registry(std::string_view text, const std::filesystem::path& origin,
                                   const OrganRegistry& base = {});

/// "wall_body", "tube", "solid" or "none".
std::string_view mesh_model_name(OrganMeshModel m);

/// The registry a directory's manifest names (its case's registry file), else the embedded one.
/// A registry file that has gone missing is an InputError naming it.
OrganRegistry registry_of_output(const std::filesystem::path& out_dir);

/// What the mesh stage needs of an organ; `wall_mm` overrides the registry's wall per organ.
MeshOrganSpec mesh_spec(const OrganInfo& organ, const std::map<std::string, double>& wall_mm = {});

/// A region's law from its material reference: a preset id of data/materials.toml, or the
/// path of an `organsmith calibrate` params.json (ends in ".json"). UsageError / InputError
/// naming what is wrong.
physics::RegionLaw region_law(const std::string& ref);
bool is_calibration_ref(const std::string& ref);

/// The solver material of every tet region of the registry's organs: the Ogden form fitted to
/// the region's calibrated law (physics/materials/solver_fit.h).
std::map<std::string, SolverMaterial> region_materials(const OrganRegistry& registry);

/// The P5/P50/P95 variants of every tet region's solver material (physics/materials/
/// material_band.h), by member name ("p05", …) then region. InputError (exit 21) naming the
/// region's material when it carries no spread.
std::map<std::string, std::map<std::string, SolverMaterial>> region_band_materials(const OrganRegistry& registry,
                                                                                    const std::vector<std::string>& organs);

/// The solver fit of a material reference as JSON (coefficients, range, errors), and the law
/// itself sampled as a uniaxial nominal-stress curve [[stretch, Pa], …] over its range.
nlohmann::json solver_material_json(const std::string& ref);
nlohmann::json uniaxial_curve_json(const std::string& ref);

/// materials.json of the attach stage: per region of `organs`, its preset (or calibration),
/// model, parameters with units, calibrated range, the law as a uniaxial curve and its solver
/// fit; with `band`, the material band (its variants' solver fits and uniaxial curves).
nlohmann::json materials_json_for(const OrganRegistry& registry, const std::vector<std::string>& organs,
                                  bool band = false);

}  // namespace organsmith
