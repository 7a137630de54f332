#pragma once
// A calibrated law's spread carried to the solver: P5 / P50 / P95 variants of a region's solver
// material. The law's parameters are drawn from independent normals with the spread its source
// gives (the thesis' sd of Table 5.1.1/5.1.2, or `calibrate`'s standard errors), the law's
// loading paths (those solver_fit.h fits and compares) are sampled for every draw, and at every
// stretch the P-th percentile of the drawn stresses is taken. Each percentile curve is then fitted
// by the same Ogden solid as the law itself (fit_solver_curves), so a solver run with the P5 and
// P95 variants brackets the organ's answer over the tissue's measured spread.
//
// Why percentiles of the response rather than of each parameter: the Fung laws are exponential in
// a1, a2, a4, so a parameter set at its own 5th percentile is not the 5th percentile of the stress,
// and parameters that stiffen one path soften none. Pointwise percentiles of increasing curves are
// increasing, so every variant is a valid law to fit. The parameters are drawn independently
// (the thesis prints no correlations), which widens the band where they are in fact correlated.

#include "physics/materials/solver_fit.h"

#include <cstdint>
#include <string>
#include <vector>

namespace organsmith::physics {

struct MaterialBandOptions {
  int draws = 2000;            ///< Monte Carlo draws of the parameters
  std::uint64_t seed = 1;      ///< fixed: the same law gives byte-identical variants
  std::vector<double> levels = {0.05, 0.50, 0.95};
  SolverFitOptions fit;
};

struct MaterialBandMember {
  std::string name;            ///< "p05", "p50", "p95"
  double level = 0.5;          ///< the percentile as a fraction
  SolverFit fit;               ///< its curves hold the percentile stresses and the fitted solid's
};

struct MaterialBand {
  std::string spread_kind;     ///< "sd", "dc_sd", "standard_error", …
  int draws = 0;               ///< draws made
  int rejected_draws = 0;      ///< draws whose law was not a tissue in tension (stress ≤ 0 or falling)
  std::vector<MaterialBandMember> members;
};

/// The band of `law`. InputError (exit 21) when the law carries no spread or too few draws are
/// valid; the fits' own errors as fit_solver_material.
MaterialBand material_band(const RegionLaw& law, const MaterialBandOptions& options = {});

/// "p05" for 0.05, "p50" for 0.5, …
std::string band_member_name(double level);

}  // namespace organsmith::physics
