#pragma once
// Gradient vector flow (Xu & Prince, "Snakes, shapes and gradient vector flow", IEEE TIP 1998):
// the field (u, v) minimising
//     ∬ μ (|∇u|² + |∇v|²) + |∇f|² |(u, v) − ∇f|² dx dy
// for an edge map f. Its Euler–Lagrange equations are
//     μ ∇²u − b (u − f_x) = 0,   μ ∇²v − b (v − f_y) = 0,   b = f_x² + f_y²,
// solved here on the pixel grid (h = 1) with zero-flux (replicated) borders, either by the
// explicit iteration of the paper (`gvf_jacobi`) or by multigrid (`gvf_multigrid`), which reaches
// the steady state in a few V-cycles where the explicit scheme needs thousands of iterations to
// diffuse the field across a slice.

#include "segmentation/image2d.h"

namespace organsmith::seg {

/// A GVF field in pixel units: u along x (columns), v along y (rows).
struct GvfField {
  Image2f u, v;
};

/// Options of the explicit (Jacobi) iteration u ← u + Δt (μ ∇²u − b (u − f_x)).
struct GvfOptions {
  double mu = 0.2;          ///< regularisation μ, pixel units (default 0.2; the paper uses 0.1–0.2)
  int iterations = 80;      ///< number of explicit steps (default 80)
  /// Time step Δt. 0 (default) picks the largest step for which every update is a convex
  /// combination of old values and the data term, i.e. 1 − Δt (4μ + b_max) ≥ 0, so the
  /// iteration obeys a maximum principle and cannot oscillate: Δt = 1 / (4μ + b_max).
  /// Xu & Prince's bound Δt ≤ 1/(4μ) (eq. 18; what ITK uses) ignores the data term.
  double time_step = 0.0;
  bool parallel = true;     ///< split rows across TBB workers (default true)
};

/// Buffers reused between calls so repeated GVF runs on same-size slices do not allocate.
struct GvfWorkspace {
  Image2f fx, fy, b, u_next, v_next;
};

/// Central-difference gradient of f in pixel units (one-sided at the borders); the GVF's data.
void edge_gradient(const Image2f& f, Image2f& fx, Image2f& fy);

/// The stable time step `GvfOptions::time_step = 0` resolves to for this edge map.
double gvf_stable_time_step(const Image2f& f, double mu);

/// Explicit GVF iteration starting from (u, v) = ∇f. `out` and `ws` are resized as needed.
void gvf_jacobi(const Image2f& f, const GvfOptions& options, GvfField& out, GvfWorkspace& ws);
GvfField gvf_jacobi(const Image2f& f, const GvfOptions& options);

/// Options of the multigrid solver of the steady-state equations (b − μ∇²) u = b f_x.
struct GvfMultigridOptions {
  double mu = 0.2;              ///< regularisation μ, pixel units (default 0.2)
  int max_cycles = 12;          ///< V-cycles at most (default 12)
  double tolerance = 1e-5;      ///< stop when max |residual| ≤ tolerance · max |b f| (default 1e-5)
  int smoothing_sweeps = 2;     ///< red-black Gauss–Seidel sweeps before and after each coarse correction
};

/// Steady-state GVF by cell-centred multigrid V-cycles (red-black Gauss–Seidel smoothing,
/// 2×2 averaging restriction, bilinear prolongation, rediscretised coarse operators).
/// Returns the number of V-cycles used through `cycles` when not null.
GvfField gvf_multigrid(const Image2f& f, const GvfMultigridOptions& options, int* cycles = nullptr);

}  // namespace organsmith::seg
