#pragma once
// A tetrahedral finite-element model of an organ with its calibrated hyperelastic law, for the
// haptic loop and the preview: total-Lagrangian, large deformation, the Ogden solid of the solver
// files (ogden_solid.h), linear (4-node, one point) or quadratic (10-node, four points,
// CalculiX C3D10 node order) tetrahedra. Solved quasi-statically (Newton with an energy line
// search) or in time (backward Euler, lumped mass, mass-proportional damping: unconditionally
// stable for any stiffness). The sparse tangent's pattern is analysed once; each Newton step
// assembles it in place and factorises it with CHOLMOD's supernodal Cholesky (LDLᵀ past a
// limit point).
//
// Boundary conditions: a fixed node set (every component zero) and a "held" node set that moves
// with one common displacement (the probe, or the tool's grip); the force on the held set is the
// sum of the internal forces at its nodes (the reaction the tool feels, with its sign reversed).
//
// Units: mm, N, s, moduli in N/mm² (MPa), density in t/mm³.

#include "physics/tissue/ogden_solid.h"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

namespace organsmith::physics {

struct TissueMesh {
  std::vector<Eigen::Vector3d> nodes_mm;
  int nodes_per_element = 4;  ///< 4 or 10
  std::vector<std::array<std::int32_t, 10>> elements;
  std::vector<std::int32_t> law_of_element;  ///< index into laws
  std::vector<OgdenSolid> laws;
};

/// The linear mesh on a quadratic mesh's corner nodes. `new_id` (optional) receives, per node of
/// `quadratic`, its id in the result (−1 for mid-edge nodes).
TissueMesh corner_mesh(const TissueMesh& quadratic, std::vector<std::int32_t>* new_id = nullptr);

struct NewtonOptions {
  int max_iterations = 25;
  double force_tolerance_N = 1e-7;   ///< largest free residual component
  double relative_tolerance = 1e-6;  ///< … or this fraction of the held set's force
  /// Asked before each iteration: true stops the solve unconverged (the caller's question has
  /// changed, e.g. the tool was withdrawn). Empty: never.
  std::function<bool()> abandon;
};

struct NewtonReport {
  bool converged = false;
  int iterations = 0;
  double residual_N = 0.0;  ///< largest free residual component at the end
  bool refreshed = false;           ///< the tangent was assembled and factorised in this call
};

struct TissueModelOptions {
  /// Linear tetrahedra: the volumetric energy per node (average nodal pressure, Bonet & Burton
  /// 1998; the linear tetrahedron of real-time surgical simulation, Joldes et al. 2009):
  /// Π_vol = Σ_n V_n K_n/2 (J_n − 1)², J_n the node's share of current over reference volume of
  /// its elements. One pressure per element locks a nearly incompressible solid (TISSUE.md has
  /// the figures). Ignored for quadratic tetrahedra (four points, as the solver).
  bool nodal_volume = true;
  /// Threads for the sparse Cholesky's dense blocks (OpenBLAS, process-wide, set when a model is
  /// made): 1 beside a display and a haptic loop; 2 on two cores with nothing else to draw
  /// (10-node gallbladder: 90 ms a factorisation against 150 ms on one).
  int solver_threads = 1;
};

class TissueModel {
 public:
  /// Throws InputError (exit 18) on an empty mesh, a node id out of range, a law index out of
  /// range or an element with non-positive volume.
  explicit TissueModel(TissueMesh mesh, TissueModelOptions options = {});
  ~TissueModel();
  TissueModel(const TissueModel&) = delete;
  TissueModel& operator=(const TissueModel&) = delete;

  const TissueMesh& mesh() const { return mesh_; }
  std::size_t node_count() const { return mesh_.nodes_mm.size(); }
  std::size_t element_count() const { return mesh_.elements.size(); }

  /// Fixed nodes (never move) and held nodes (move together by `set_held_displacement`). The
  /// two sets may overlap (fixed wins). Changing them keeps the current displacement.
  void set_boundary(std::vector<std::int32_t> fixed, std::vector<std::int32_t> held);
  const std::vector<std::int32_t>& held_nodes() const { return held_; }

  /// Quasi-static equilibrium with the held nodes at `held_mm` (from the current state).
  NewtonReport solve_static(const Eigen::Vector3d& held_mm, const NewtonOptions& options = {});
  /// One backward-Euler step of `dt_s` with the held nodes at `held_mm` at its end.
  NewtonReport step_dynamic(const Eigen::Vector3d& held_mm, double dt_s, const NewtonOptions& options = {});

  /// Quasi-static equilibrium with the held nodes at `held_mm` by BFGS (Matthies & Strang 1979):
  /// the last factorised tangent (of this boundary, static) as the initial inverse Hessian,
  /// updated by the secant pairs of the iterations (at most `options.max_iterations`, a residual
  /// and a back-substitution each), with a backtracking line search on the energy. Where there is
  /// no such tangent, or the iterations do not converge, one Newton iteration refactorises it and
  /// the iterations go on from there (at most twice). The held-set stiffness and response are
  /// the last factorisation's. `refreshed` says whether this call factorised.
  NewtonReport solve_static_quasi_newton(const Eigen::Vector3d& held_mm, const NewtonOptions& options);
  const TissueModelOptions& options() const { return options_; }

  /// Sum of internal forces over the held nodes at the current state (N): the force the tissue
  /// exerts on whatever holds them is its negative.
  Eigen::Vector3d held_force_N() const;
  /// d(held_force)/d(held displacement) at the current state with every free node in
  /// equilibrium (the Schur complement of the tangent on the held set's translation; for a
  /// dynamic step it includes the step's inertia). Valid after a solve.
  Eigen::Matrix3d held_stiffness_N_per_mm() const { return held_stiffness_; }
  /// d(displacement)/d(held displacement) at the same state (3 per node × 3): the whole model's
  /// first-order response to a motion of the held set, the free nodes in equilibrium (identity
  /// rows at the held nodes, zero at the fixed ones). Valid after a solve with a held set.
  const Eigen::MatrixXd& held_response() const { return held_response_; }

  const Eigen::VectorXd& displacement_mm() const { return u_; }
  /// Back to a displacement this model had (velocity zero), e.g. the last equilibrium after an
  /// increment that did not converge. Its size must be 3 per node.
  void set_displacement_mm(const Eigen::VectorXd& u);
  void reset();  ///< back to rest (zero displacement and velocity)
  double strain_energy_mJ() const;  ///< N·mm
  /// Largest principal stretch per element (from its mean deformation gradient) at the current state.
  std::vector<double> element_max_stretch() const;
  /// Von Mises Cauchy stress per element at the current state (N/mm²).
  std::vector<double> element_von_mises() const;

  double density_t_per_mm3 = 1.05e-9;  ///< tissue, 1050 kg/m³
  double damping_per_s = 8.0;           ///< mass-proportional damping coefficient

 private:
  struct Impl;
  TissueMesh mesh_;
  TissueModelOptions options_;
  std::unique_ptr<Impl> impl_;
  std::vector<std::int32_t> fixed_, held_;
  Eigen::VectorXd u_, v_;  ///< displacement (mm), velocity (mm/s)
  Eigen::Matrix3d held_stiffness_ = Eigen::Matrix3d::Zero();
  Eigen::MatrixXd held_response_;
  NewtonReport newton(const Eigen::Vector3d& held_mm, double dt_s, const NewtonOptions& options);
  std::uint64_t boundary_version_ = 0;
};

}  // namespace organsmith::physics
