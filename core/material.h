#pragma once
// A constitutive model with its parameter values, units and provenance.

#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// One named parameter with its unit ("Pa", "1" for dimensionless, …).
struct MaterialParameter {
  std::string name;
  double value = 0.0;
  std::string unit;
};

/// A material: which model (e.g. "fung-wall", "mooney-rivlin"), its parameters, and where the
/// numbers come from (thesis table/equation, or a calibration run).
struct Material {
  std::string model;
  std::vector<MaterialParameter> parameters;
  std::string source;

  /// Value of parameter `name`, if present.
  std::optional<double> parameter(const std::string& name) const;
};

/// A calibrated law in the form finite-element solvers take, fitted to the law's own response
/// (physics/materials/solver_fit.h). Ogden in the Abaqus/CalculiX convention
///   W = Σ 2μi/αi² (λ̄1^αi + λ̄2^αi + λ̄3^αi − 3) + (J − 1)²/D1,  D1 = 2/K,
/// so that the initial shear modulus is Σ μi and the bulk modulus K. FEBio's "Ogden" takes
/// c_i = 2μi, m_i = αi and k = K.
struct SolverMaterial {
  std::string law_id;            ///< preset id or calibration file the law came from
  std::string law_model;         ///< "fung-wall", "fung-organ", "mooney-rivlin", …
  std::vector<double> ogden_mu_Pa, ogden_alpha;
  double bulk_modulus_Pa = 0.0;
  std::string bulk_source;       ///< where K comes from (the law's volumetric term, or K/μ0)
  double stretch_max = 1.0;      ///< fitted over stretches [1, stretch_max]
  double max_relative_error = 0.0;  ///< largest |fit − law|/|law| over the fitted curves
  std::string curves;            ///< which responses were fitted ("uniaxial circumferential, …")
  std::string note;              ///< one line of provenance for file comments
};

}  // namespace organsmith
