#pragma once
// The compressible Ogden solid of the solver files (CalculiX/Abaqus *HYPERELASTIC, OGDEN):
//   W = Σ_i 2 μ_i/α_i² (λ̄1^α_i + λ̄2^α_i + λ̄3^α_i − 3) + K/2 (J − 1)²,   λ̄_a = J^(−1/3) λ_a,
// evaluated at a deformation gradient: energy, second Piola–Kirchhoff stress and the material
// tangent ∂S/∂E, from the principal stretches (Holzapfel, Nonlinear Solid Mechanics, 6.196–6.197;
// the derivation is in TISSUE.md). Mooney–Rivlin and neo-Hookean laws are Ogden terms with α = ±2.
//
// Units: any consistent set; organsmith uses mm and N, so moduli in N/mm² (MPa).

#include <Eigen/Core>

#include <vector>

namespace organsmith::physics {

struct OgdenSolid {
  std::vector<double> mu, alpha;  ///< μ_i (Abaqus form: initial shear modulus Σ μ_i), α_i
  double bulk = 0.0;              ///< K = 2 / D1
  double initial_shear() const;
};

/// Voigt order 11, 22, 33, 12, 23, 31; shear strains engineering (2 E12, …).
using Voigt6 = Eigen::Matrix<double, 6, 1>;
using Tangent6 = Eigen::Matrix<double, 6, 6>;

struct SolidPoint {
  double energy = 0.0;                              ///< W per reference volume
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();      ///< second Piola–Kirchhoff stress
  Tangent6 D = Tangent6::Zero();                    ///< ∂S/∂E (when asked for)
};

/// Evaluates the law at F. False when det F ≤ 0 (an inverted element); `out` is then untouched.
bool evaluate_ogden(const OgdenSolid& law, const Eigen::Matrix3d& F, SolidPoint& out, bool with_tangent);

}  // namespace organsmith::physics
