#pragma once
// Calibrated laws in the form solvers take. The thesis' Fung laws (and any calibrated law) have
// no counterpart in CalculiX/Abaqus or FEBio, so each region's law is sampled along the loading
// paths its data came from (uniaxial in both in-plane directions, and equibiaxial for the
// membrane laws) over the calibrated stretch range, and a three-term incompressible Ogden solid
// is fitted to those samples by least squares on relative residuals. The Ogden terms are kept
// with μi αi > 0 (each term stiffens; Ogden's sufficient condition for a positive tangent in
// every deformation), and the fit's tangent dT/dλ is checked positive along every fitted path.
//
// Why one isotropic form: the solvers' anisotropic laws need fibre directions, which a CT does
// not give. For the Fung laws with a1 ≠ a2 the fit lies between the two directions, and
// `max_relative_error` says how far from each.

#include "core/material.h"
#include "physics/materials/models.h"
#include "physics/materials/presets.h"

#include <filesystem>
#include <string>
#include <vector>

namespace organsmith::physics {

/// One loading path of a law, sampled: nominal stress (Pa) at stretches in (1, stretch_max].
struct LawCurve {
  std::string name;           ///< "uniaxial circumferential", "equibiaxial", …
  LoadCase load = LoadCase::uniaxial_circumferential;
  bool equibiaxial = false;   ///< lateral stretch = stretch
  bool fitted = true;         ///< part of the fit (else only compared, see solver_fit.cpp)
  bool direction_mean = false;  ///< the mean of the two uniaxial directions (membrane laws)
  std::vector<double> stretch;
  std::vector<double> nominal_stress_Pa;
  std::vector<double> fitted_stress_Pa;   ///< the solver form on the same stretches
  double max_relative_error = 0.0;
};

/// A law to put on a region: which model with which parameters, its constants and the range
/// of stretches its parameters were calibrated over.
struct RegionLaw {
  std::string id;              ///< preset id, or the calibration file
  Material material;
  ModelOptions options;        ///< bulk modulus, …
  double stretch_max = 1.0;    ///< top of the calibrated range (> 1)
  std::string range_source;    ///< where the range comes from
  /// Standard deviations of the parameters (same names as material), for material bands.
  std::vector<MaterialParameter> sd;
  std::string sd_kind;         ///< "sd", "imvfosm_sd", … ("" when none)
};

struct SolverFitOptions {
  int samples = 24;             ///< stretches per loading path, evenly spaced in (1, stretch_max]
  /// K over the largest tangent shear modulus of the fitted response over the range: the solid
  /// stays nearly incompressible (ν ≥ 0.49) up to the top of the range, as the fit assumes.
  double bulk_to_shear = 50.0;
};

/// The fit and the law it came from.
struct SolverFit {
  SolverMaterial material;          ///< what the writers put in the files
  std::vector<LawCurve> curves;     ///< the law and the fit along every fitted path
  double min_tangent_Pa = 0.0;      ///< smallest dT/dλ of the fit over the fitted paths
  bool stable = false;              ///< min_tangent_Pa > 0 and every μi αi > 0
};

/// Fits the solver form to `law`. Throws UsageError for laws with no continuum form
/// (kelvin-cutting) and InputError when the fit is unstable or cannot be made.
SolverFit fit_solver_material(const RegionLaw& law, const SolverFitOptions& options = {});

/// The same fit to given samples of the law's paths (as law_curves makes them, with other
/// stresses: a material band's percentile curves, see material_band.h).
SolverFit fit_solver_curves(const RegionLaw& law, std::vector<LawCurve> curves, const SolverFitOptions& options = {});

/// The law's loading paths that a solver form should reproduce: uniaxial (both in-plane
/// directions for the membrane laws) and, for the membrane laws, equibiaxial.
std::vector<LawCurve> law_curves(const RegionLaw& law, int samples);

/// Nominal stress (Pa) of an Ogden solid in the Abaqus convention, incompressible, along a path
/// (uniaxial, or equibiaxial when `equibiaxial`).
double ogden_nominal_Pa(const SolverMaterial& m, double stretch, bool equibiaxial);

/// The membrane Fung law W = c/2 (e^Q − 1), Q = a1 Eθ² + a2 Ez² + 2 a4 Eθ Ez (thesis 5.1.3; a1
/// circumferential, a2 longitudinal) as FEBio's Fung-ortho-compressible law with axes 1 =
/// longitudinal, 2 = circumferential, 3 = wall normal. FEBio's normal-strain stiffness is the
/// inverse of the orthotropic compliance, ℂ = c A, so A padded to 3×3 with no coupling to the
/// normal and a33 = 10⁻³ min(a1, a2) (FEBio needs E3 > 0) gives
///   E1 = c (a2 − a4²/a1), E2 = c (a1 − a4²/a2), E3 = c a33, v12 = a4/a1, v23 = v31 = 0,
/// which reproduces the membrane law in plane stress for any k to O(a33) (0.2 %, measured in
/// tests). The law has no shear term; G12 = G23 = G31 = c √(a1 a2)/4 is an assumption (it does not
/// enter loading along the axes). `k_Pa` sets the through-thickness and volume stiffness only.
FebioFungOrthotropic febio_fung_form(double c_Pa, double a1, double a2, double a4, double k_Pa);

/// A region law from the built-in presets (`id` of data/materials.toml); UsageError when the
/// preset does not exist, InputError when it has no calibrated range.
RegionLaw region_law_from_preset(const MaterialLibrary& library, const std::string& id);

/// A region law from `organsmith calibrate` output (params.json; the range from its
/// `stretch_range`, else from fit.csv beside it). InputError naming the file when it is not one.
RegionLaw region_law_from_calibration(const std::filesystem::path& params_json);

}  // namespace organsmith::physics
