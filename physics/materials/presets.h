#pragma once
// The thesis' parameter sets (data/materials.toml, embedded at build time) as Materials.

#include "core/material.h"
#include "physics/materials/models.h"

#include <Eigen/Core>

#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace organsmith::physics {

/// One parameter set with its spreads and the figures the thesis printed next to it.
struct MaterialPreset {
  std::string id;                 ///< "fung-wall/table-5.1.1/mean", …
  Material material;              ///< model, parameters (with units), source
  /// Standard deviations by kind ("sd", "dc_sd", "imvfosm_sd"), same names and units.
  std::map<std::string, std::vector<MaterialParameter>> spreads;
  std::map<std::string, double> constants;   ///< e.g. blade_speed_m_per_s, bulk_modulus_Pa
  std::map<std::string, double> fit;         ///< printed R², RMSE, seconds
  /// Top of the stretch range the parameters were calibrated over (0 = not given), and where
  /// that range comes from. A solver form is fitted over [1, stretch_max] (solver_fit.h).
  double stretch_max = 0.0;
  std::string range_source;
};

/// A printed table of ∂f/∂Ci and σ_T at several stretches (Tables 4.1.2/4.1.3).
struct DerivativeTable {
  std::string id, direction, source;
  std::vector<double> stretch;
  std::vector<double> sigma_T_Pa;
  Eigen::MatrixXd dfdC;   ///< rows = stretches, columns = C1…C7
};

struct MaterialLibrary {
  std::vector<MaterialPreset> materials;
  std::vector<DerivativeTable> derivative_tables;

  /// Throws UsageError listing the ids when `id` is unknown.
  const MaterialPreset& find(const std::string& id) const;
  const DerivativeTable& table(const std::string& id) const;
};

/// Parses a materials TOML text (format of data/materials.toml). Throws CaseFileError on a
/// malformed file, naming `source`.
MaterialLibrary parse_material_library(const std::string& toml_text, const std::filesystem::path& source);

/// The library embedded from data/materials.toml.
MaterialLibrary builtin_material_library();

/// Values of `m`'s parameters in `model`'s order; UsageError when one is missing.
std::vector<double> parameter_values(const Model& model, const std::vector<MaterialParameter>& m);

/// ModelOptions with the preset's constants applied (bulk modulus, blade speed).
ModelOptions model_options_for(const MaterialPreset& preset, ModelOptions base = {});

}  // namespace organsmith::physics
