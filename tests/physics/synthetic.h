#pragma once
// Synthetic test curves: a model evaluated at a parameter set, with 2 % multiplicative Gaussian
// noise (each stress multiplied by 1 + 0.02·N(0,1)), as in the round-trip criteria.

#include "physics/materials/calibration.h"
#include "physics/materials/models.h"

#include <vector>

namespace organsmith::physics::testing {

/// `per_direction` stretches evenly in (1, max_stretch] along each listed load case.
inline CalibrationData uniaxial_curves(const Model& m, const std::vector<double>& p,
                                       const std::vector<LoadCase>& loads, int per_direction,
                                       double max_stretch, double noise, std::uint64_t seed) {
  CalibrationData d;
  Rng rng(seed);
  for (LoadCase l : loads)
    for (int i = 1; i <= per_direction; ++i) {
      const double x = 1.0 + (max_stretch - 1.0) * i / per_direction;
      d.points.push_back({x, 1.0, l});
      d.specimen.push_back(l == LoadCase::uniaxial_longitudinal ? "long" : "circ");
    }
  d.measured.resize(d.points.size());
  m.respond(d.points, p, d.measured);
  for (double& y : d.measured) y *= 1.0 + noise * rng.normal();
  d.source = "synthetic";
  return d;
}

/// Planar biaxial protocol: each axis stretched to 1.0…max while the other is held at 1.0, 1.15
/// and max; both stresses recorded.
inline CalibrationData biaxial_curves(const Model& m, const std::vector<double>& p, int steps,
                                      double max_stretch, double noise, std::uint64_t seed) {
  CalibrationData d;
  Rng rng(seed);
  for (LoadCase l : {LoadCase::biaxial_circumferential, LoadCase::biaxial_longitudinal})
    for (double hold : {1.0, 1.15, max_stretch})
      for (int i = 1; i <= steps; ++i) {
        const double x = 1.0 + (max_stretch - 1.0) * i / steps;
        d.points.push_back({x, hold, l});
        d.specimen.push_back("");
      }
  d.measured.resize(d.points.size());
  m.respond(d.points, p, d.measured);
  for (double& y : d.measured) y *= 1.0 + noise * rng.normal();
  d.source = "synthetic";
  return d;
}

/// Cutting force curve for u in (0, max_u].
inline CalibrationData cutting_curve(const Model& m, const std::vector<double>& p, int n, double max_u,
                                     double noise, std::uint64_t seed) {
  CalibrationData d;
  Rng rng(seed);
  for (int i = 1; i <= n; ++i) {
    d.points.push_back({max_u * i / n, 1.0, LoadCase::displacement});
    d.specimen.push_back("");
  }
  d.measured.resize(d.points.size());
  m.respond(d.points, p, d.measured);
  for (double& y : d.measured) y *= 1.0 + noise * rng.normal();
  d.source = "synthetic";
  return d;
}

}  // namespace organsmith::physics::testing
