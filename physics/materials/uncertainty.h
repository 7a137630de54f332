#pragma once
// Parameter uncertainty (thesis §4.1.2.3–4.1.4): the direct-calculation (DC) method, the inverse
// mean-value first-order second-moment (IMVFOSM) method, Monte Carlo propagation to stress CDFs,
// and the 3σ envelope check.

#include "physics/materials/calibration.h"
#include "physics/materials/models.h"

#include <Eigen/Core>

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace organsmith::physics {

/// Mean and standard deviation of the stress at each point (Pa).
struct StressMoments {
  std::vector<double> mean_Pa;
  std::vector<double> sd_Pa;
};

/// First-order prediction (thesis 4.1.14–4.1.15) for independent parameters with means `mean` and
/// standard deviations `sd`: μ_T = f(μ_C), σ_T = √Σ (∂f/∂Ci σ_Ci)².
StressMoments linearised_moments(const Model& model, std::span<const LoadPoint> points,
                                 std::span<const double> mean, std::span<const double> sd);

/// Second-order moments of the Taylor expansion to quadratic terms (independent normal
/// parameters): μ ≈ f + ½ Σ f_ii σi², σ² ≈ Σ (f_i σi)² + ½ ΣΣ (f_ij σi σj)². The difference to
/// linearised_moments() is the estimate of the linearisation error. The Hessian f_ij is formed by
/// central differences of the analytic gradient (step `rel_step` × max(|μi|, σi)).
StressMoments second_order_moments(const Model& model, std::span<const LoadPoint> points,
                                   std::span<const double> mean, std::span<const double> sd,
                                   double rel_step = 1e-4);

/// IMVFOSM inverse: given ∂f/∂Ci at each strain stage (rows = stages, columns = parameters) and
/// the measured σ_T per stage, find σ_C ≥ 0 such that Σi (∂f/∂Ci σ_Ci)² ≈ σ_T² at every stage.
/// The unknowns s_i = σ_Ci² enter linearly, so this is a non-negative least-squares problem; with
/// `relative` each stage's equation is divided by σ_T² so that the small-stretch stages count as
/// much as the large ones. The solution is generally not unique (the thesis notes that its GA
/// picks one of many); NNLS returns the one with the fewest non-zero σ's that fits best.
struct ImvfosmResult {
  std::vector<double> sigma;             ///< σ_C, parameter units
  std::vector<double> predicted_sd_Pa;   ///< √Σ (∂f/∂Ci σ_Ci)² per stage
  double rms_relative_error = 0.0;       ///< RMS over stages of (predicted − σ_T)/σ_T
};
ImvfosmResult imvfosm_solve(const Eigen::MatrixXd& dfdC, std::span<const double> sigma_T_Pa,
                            bool relative = true);

/// σ_T predicted from given σ_C by 4.1.14 (used to check a printed σ_C row against its σ_T).
std::vector<double> imvfosm_forward(const Eigen::MatrixXd& dfdC, std::span<const double> sigma_C);

/// Monte Carlo propagation: `samples` draws of independent normal parameters, the stress at every
/// point for each draw. Draws where the model is undefined (NaN stress at any point) are counted
/// and left out of the statistics.
struct MonteCarloOptions {
  int samples = 10000;
  std::uint64_t seed = 1;
};
struct MonteCarloResult {
  /// stress_Pa(s, k): draw s at point k, valid draws only (rows = valid draws).
  Eigen::MatrixXd stress_Pa;
  int invalid_draws = 0;
  StressMoments moments;   ///< sample mean and standard deviation of the valid draws
  std::vector<double> median_Pa;
  std::vector<double> robust_sd_Pa;   ///< interquartile range / 1.349 (= σ for a normal)
};
MonteCarloResult monte_carlo(const Model& model, std::span<const LoadPoint> points,
                             std::span<const double> mean, std::span<const double> sd,
                             const MonteCarloOptions& options = {});

/// Empirical CDF of column k of a Monte Carlo result at `levels` probabilities: the stress below
/// which that fraction of draws lies (linear interpolation between order statistics).
std::vector<double> stress_quantiles(const MonteCarloResult& mc, int k, std::span<const double> levels);

/// The DC method: fit every specimen separately and take the spread of the fitted parameters
/// (population standard deviation, as thesis 4.1.2).
struct DirectCalculation {
  std::vector<std::string> specimens;
  std::vector<FitResult> fits;
  std::vector<double> mean;
  std::vector<double> sd;
};
DirectCalculation direct_calculation(const Model& model, const CalibrationData& data,
                                     const FitOptions& options);

/// 3σ check (thesis §4.1.4): the fraction of a reference curve's points that lie within
/// [μ − 3σ, μ + 3σ] of the predicted stress distribution.
struct EnvelopeCheck {
  double fraction_inside = 0.0;
  std::vector<bool> inside;
};
EnvelopeCheck three_sigma_check(const StressMoments& predicted, std::span<const double> curve_Pa);

}  // namespace organsmith::physics
