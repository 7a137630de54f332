#pragma once
// Calibration of a Model to measured curves: the CSV reader with validation, the thesis' genetic
// algorithm (§4.1.2.2, §5.1.3; eqs 3.12–3.17) and a Levenberg–Marquardt polish that uses the
// models' analytic parameter derivatives.

#include "core/errors.h"
#include "core/progress.h"
#include "physics/materials/models.h"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace organsmith::physics {

/// Measured data that a calibration or uncertainty analysis cannot use (exit code 21).
class CalibrationDataError : public InputError {
 public:
  CalibrationDataError(std::string message, std::filesystem::path path = {}, std::string hint = {})
      : InputError(ExitCode::calibration_data, std::move(message), std::move(path), std::move(hint)) {}
};

/// Measured points of one or more specimens. measured[i] is the nominal stress in Pa (or the
/// force in N for LoadCase::displacement) recorded at points[i].
struct CalibrationData {
  std::vector<LoadPoint> points;
  std::vector<double> measured;
  std::vector<std::string> specimen;   ///< per point; "" when the file has no specimen column
  std::filesystem::path source;        ///< where the data came from (for messages)
  /// Optional residual weights (empty = all 1): the fit minimises Σ (w_i (f_i − y_i))². The
  /// thesis' fitness (3.16) is unweighted; see use_relative_residuals().
  std::vector<double> weight;
};

/// Sets weights 1/|y_i| so that the fit minimises squared relative residuals — the maximum-
/// likelihood choice when the measurement error is proportional to the stress (load cells with a
/// relative accuracy). |y_i| is floored at `floor_fraction` × max|y| so that points at zero load do
/// not dominate. Fit statistics (SSE, R², RMSE) are still reported unweighted.
void use_relative_residuals(CalibrationData& data, double floor_fraction = 0.01);

/// Reads calibration data from CSV. Header (case-insensitive, any column order):
///   stress tests: `stretch` (1) or `strain` (1, stretch = 1 + strain), `stress_pa`, optional
///   `direction` (`circumferential` | `longitudinal`, default circumferential), optional
///   `specimen`, optional `lateral_stretch` (makes the row biaxial: the other in-plane stretch
///   is prescribed and the stress is the one along `direction`);
///   cutting tests (`displacement = true`): `displacement_m`, `force_n`, optional `specimen`.
/// Throws CalibrationDataError naming file, line and column for: missing columns, unparsable or
/// non-finite numbers, stretch ≤ 0, stretch not strictly increasing within a specimen and
/// direction, and fewer than `min_points` rows.
CalibrationData read_calibration_csv(const std::filesystem::path& path, bool displacement,
                                     std::size_t min_points);

/// Same, from text already in memory (`source` names it in messages).
CalibrationData parse_calibration_csv(const std::string& text, const std::filesystem::path& source,
                                      bool displacement, std::size_t min_points);

/// Goodness of fit of predicted against measured values.
struct FitStatistics {
  double sse = 0.0;    ///< Σ (predicted − measured)², measured unit squared (Pa² or N²)
  double r2 = 0.0;     ///< 1 − SSE/SST (coefficient of determination)
  double rmse = 0.0;   ///< √(SSE/n), measured unit
};
FitStatistics fit_statistics(std::span<const double> measured, std::span<const double> predicted);

/// Genetic-algorithm settings; the defaults are the thesis' §5.1.3 run (population 200, 10 %
/// selection, crossover fraction 0.7, 200 generations). Interpretation (the thesis used MATLAB's
/// ga and names only these numbers): the best `selection_fraction` of each generation pass on
/// unchanged (elitism); of the other children, `crossover_fraction` come from blend crossover
/// of two tournament winners and the rest from Gaussian mutation of one, with a step that shrinks
/// linearly over the generations. Search happens in the box scaled to [0, 1]ⁿ.
struct GaOptions {
  int population = 200;
  int generations = 200;
  double selection_fraction = 0.1;
  double crossover_fraction = 0.7;
  double mutation_scale = 0.15;   ///< initial mutation σ as a fraction of each box width
  std::uint64_t seed = 1;
  /// Evaluate the population with TBB when one generation takes over 0.5 ms serially (the
  /// result does not change either way).
  bool parallel = true;
};

/// Levenberg–Marquardt settings (bounded by projection onto the box).
struct LmOptions {
  int max_iterations = 200;
  double relative_tolerance = 1e-12;   ///< stop when SSE improves by less than this fraction
};

struct FitOptions {
  GaOptions ga;
  LmOptions lm;
  bool polish = true;           ///< run Levenberg–Marquardt from the GA's best individual
  std::vector<double> lower;    ///< search box; empty = the model's default intervals
  std::vector<double> upper;
};

struct FitResult {
  std::vector<double> parameters;
  std::vector<double> lower, upper;   ///< the box that was searched
  std::vector<double> predicted;      ///< model at the data points
  FitStatistics stats;
  /// Asymptotic standard errors √(s² (JᵀJ)⁻¹)_jj with s² = SSE/(n − p), parameter units. Large
  /// values (or +∞ when JᵀJ is singular) flag parameters the data cannot determine.
  std::vector<double> standard_errors;
  double ga_sse = 0.0;                ///< objective (weighted SSE) of the GA's best before the polish
  int lm_iterations = 0;
  double seconds = 0.0;               ///< wall time of the whole fit
  std::uint64_t seed = 0;
};

/// Validates a search box against `model` (sizes, finite, lower < upper) and returns it
/// (the model's defaults when both are empty). Throws UsageError naming the parameter.
void resolve_bounds(const Model& model, std::vector<double>& lower, std::vector<double>& upper);

/// GA then (optionally) LM. Deterministic for a given seed: the same data and options give
/// bit-identical parameters whether or not `parallel` is set.
FitResult calibrate(const Model& model, const CalibrationData& data, const FitOptions& options,
                    Progress* progress = nullptr);

/// Levenberg–Marquardt from `start` inside [lower, upper].
FitResult least_squares(const Model& model, const CalibrationData& data, std::vector<double> start,
                        const std::vector<double>& lower, const std::vector<double>& upper,
                        const LmOptions& options = {});

/// Baseline for the benchmark: LM from `starts` points drawn uniformly in the box; the best.
FitResult multistart_least_squares(const Model& model, const CalibrationData& data, int starts,
                                   std::uint64_t seed, const std::vector<double>& lower,
                                   const std::vector<double>& upper, const LmOptions& options = {});

/// Standard errors of `p` on `data` (see FitResult::standard_errors).
std::vector<double> standard_errors(const Model& model, const CalibrationData& data,
                                    std::span<const double> p);

/// Small deterministic generator (SplitMix64 seeding + xoshiro256**) with its own uniform and
/// normal draws, so results do not depend on the standard library's distribution code.
class Rng {
 public:
  explicit Rng(std::uint64_t seed);
  std::uint64_t next();
  double uniform();                 ///< [0, 1)
  double normal();                  ///< standard normal (Marsaglia polar)
  int below(int n) { return static_cast<int>(uniform() * n); }

 private:
  std::uint64_t s_[4];
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace organsmith::physics
