#include "physics/tissue/ogden_solid.h"

#include <Eigen/Eigenvalues>

#include <cmath>

namespace organsmith::physics {

double OgdenSolid::initial_shear() const {
  double s = 0.0;
  for (double m : mu) s += m;
  return s;
}

namespace {

// Voigt vector of a symmetric matrix (tensor components, no factor 2).
Voigt6 voigt(const Eigen::Matrix3d& m) {
  Voigt6 v;
  v << m(0, 0), m(1, 1), m(2, 2), m(0, 1), m(1, 2), m(2, 0);
  return v;
}

}  // namespace

bool evaluate_ogden(const OgdenSolid& law, const Eigen::Matrix3d& F, SolidPoint& out, bool with_tangent) {
  const double J = F.determinant();
  if (!(J > 0.0)) return false;
  const Eigen::Matrix3d C = F.transpose() * F;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(C);
  const Eigen::Vector3d lam2 = eig.eigenvalues().cwiseMax(1e-300);
  const Eigen::Matrix3d N = eig.eigenvectors();
  const double Jm13 = std::pow(J, -1.0 / 3.0);
  const std::size_t n = law.mu.size();

  // β_a = λ̄_a ∂W_dev/∂λ̄_a and its log-derivative pieces; Kirchhoff principal stress
  // τ_a = β_a − mean(β) + J K (J − 1).
  Eigen::Vector3d beta = Eigen::Vector3d::Zero(), gam = Eigen::Vector3d::Zero();  // γ_a = Σ 2 μ_i λ̄_a^α_i
  double W = 0.0;
  for (int a = 0; a < 3; ++a) {
    const double lb = Jm13 * std::sqrt(lam2[a]);
    const double llb = std::log(lb);
    for (std::size_t i = 0; i < n; ++i) {
      const double p = std::exp(law.alpha[i] * llb);
      beta[a] += 2.0 * law.mu[i] / law.alpha[i] * p;
      gam[a] += 2.0 * law.mu[i] * p;
      W += 2.0 * law.mu[i] / (law.alpha[i] * law.alpha[i]) * p;
    }
  }
  for (std::size_t i = 0; i < n; ++i) W -= 3.0 * 2.0 * law.mu[i] / (law.alpha[i] * law.alpha[i]);
  W += 0.5 * law.bulk * (J - 1) * (J - 1);
  const double bmean = beta.sum() / 3.0;
  const double tvol = J * law.bulk * (J - 1);
  Eigen::Vector3d tau, Sa;
  for (int a = 0; a < 3; ++a) {
    tau[a] = beta[a] - bmean + tvol;
    Sa[a] = tau[a] / lam2[a];
  }
  out.energy = W;
  out.S = N * Sa.asDiagonal() * N.transpose();
  if (!with_tangent) return true;

  // G_ab = λ_b ∂τ_a/∂λ_b: with ∂ln λ̄_a/∂ln λ_b = δ_ab − 1/3,
  // λ_b ∂β_a/∂λ_b = γ_a (δ_ab − 1/3), and λ_b ∂(J K (J−1))/∂λ_b = J K (2J − 1).
  Eigen::Matrix3d dbeta;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) dbeta(a, b) = gam[a] * ((a == b ? 1.0 : 0.0) - 1.0 / 3.0);
  const double dvol = J * law.bulk * (2 * J - 1);
  Eigen::Matrix3d G;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) G(a, b) = dbeta(a, b) - dbeta.col(b).sum() / 3.0 + dvol;
  // (1/λ_b) ∂S_a/∂λ_b = G_ab/(λ_a² λ_b²) − 2 δ_ab τ_a/λ_a⁴
  Eigen::Matrix3d H;
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) H(a, b) = G(a, b) / (lam2[a] * lam2[b]) - (a == b ? 2.0 * tau[a] / (lam2[a] * lam2[a]) : 0.0);

  Tangent6 D = Tangent6::Zero();
  Voigt6 v[3];
  for (int a = 0; a < 3; ++a) v[a] = voigt(N.col(a) * N.col(a).transpose());
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) D += H(a, b) * v[a] * v[b].transpose();
  // Shear terms: (S_b − S_a)/(λ_b² − λ_a²) on (N_a N_bᵀ + N_b N_aᵀ) ⊗ itself, its limit
  // ½ (H_bb − H_ab) where the stretches coincide (6.197).
  for (int a = 0; a < 3; ++a)
    for (int b = a + 1; b < 3; ++b) {
      const double d = lam2[b] - lam2[a];
      const double g = std::abs(d) > 1e-8 * (lam2[a] + lam2[b]) ? (Sa[b] - Sa[a]) / d : 0.5 * (H(b, b) - H(a, b));
      const Voigt6 m = voigt(N.col(a) * N.col(b).transpose() + N.col(b) * N.col(a).transpose());
      D += g * m * m.transpose();
    }
  out.D = D;
  return true;
}

}  // namespace organsmith::physics
