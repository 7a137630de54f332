#pragma once
// A constitutive model with its parameter values, units and provenance.

#include <array>
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

/// FEBio's "Fung-ortho-compressible" form of a membrane Fung law (thesis 5.1.3), for solvers that
/// take the law itself: W = c/2 (e^Q − 1) + k/2 (ln J)², Q = c⁻¹ Σ [2μa Aa:E² + Σ λab (Aa:E)(Ab:E)]
/// with the λ, μ of the orthotropic moduli below. Material axes: 1 = longitudinal, 2 =
/// circumferential, 3 = wall normal (given per element). Moduli in Pa.
struct FebioFungOrthotropic {
  double E1_Pa = 0, E2_Pa = 0, E3_Pa = 0;
  double G12_Pa = 0, G23_Pa = 0, G31_Pa = 0;
  double v12 = 0, v23 = 0, v31 = 0;
  double c_Pa = 0, k_Pa = 0;
  std::string note;  ///< the mapping and what it leaves to assumption
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
  /// The law itself in FEBio's Fung orthotropic form, for membrane Fung laws (fung-wall); FEB
  /// files use it with per-element material axes, other formats the Ogden fit.
  std::optional<FebioFungOrthotropic> febio_fung;
  /// The law itself where it is a Mooney–Rivlin solid, {C10, C01} in Pa: INP files write it as
  /// *HYPERELASTIC, MOONEY-RIVLIN (exact, and an invariant form whose tangent CalculiX evaluates
  /// well at small strain; its Ogden form with equal exponents stalls Newton there: the phantom's
  /// trachea at 10 Pa made 17 iterations without converging, the same model in MOONEY-RIVLIN ran
  /// to 2 kPa in 34). Other formats use the Ogden fit, which reproduces the law exactly too.
  std::optional<std::array<double, 2>> mooney_rivlin_Pa;
};

}  // namespace organsmith
