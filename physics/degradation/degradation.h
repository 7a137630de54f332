#pragma once
// Strain-energy-driven degradation of the micro-clip (thesis ch. 6): the element energy map
// (6.2–6.5), the incremental minimisation K·u = P (6.8–6.13), the degradation law
// ḋ = (1 − d)(k0 + √E*/τ_D) (6.14–6.16 plus a baseline term) integrated in time with the energy
// re-minimised as the clip weakens, element fracture, mass remaining, and the calibration of τ_D
// to a mass-remaining series (Table 6.1). Derivations and departures: physics/degradation/DEGRADATION.md.
//
// Units: mm, N, mJ (N·mm), days. E* in 6.16 is an energy density in kJ/m³ (= kPa = 1e-3 mJ/mm³)
// and τ_D is in week·(kJ/m³)^½ — the thesis states the immersion time and Fig. 6.8's stages in
// weeks (DEGRADATION.md, "Units"). Times of the API are in days.

#include "core/errors.h"
#include "core/progress.h"
#include "physics/degradation/clip.h"

#include <filesystem>
#include <string>
#include <vector>

namespace organsmith::physics {

/// 1 kJ/m³ in mJ/mm³: E* of 6.16 is expressed in kJ/m³.
inline constexpr double kEnergyDensityUnit_mJ_per_mm3 = 1e-3;
inline constexpr const char* kEnergyDensityUnitName = "kJ/m^3";
inline constexpr const char* kTauUnitName = "week*(kJ/m^3)^0.5";
/// The time unit of τ_D in days (τ_D is in weeks·(kJ/m³)^½).
inline constexpr double kTauTimeUnit_days = 7.0;

// ---- thesis 6.2–6.3 for one element -------------------------------------------------------------

/// Deflection (mm) of 6.2 at x ∈ [0, L] (mm) of a beam of length L under a force F (N) normal to
/// it at mid-span, ends held: d(x) = F x (3L²/4 − x²)/(12 E I) for x ≤ L/2, mirrored beyond.
double beam_deflection_6_2(double F_N, double E_MPa, double I_mm4, double L_mm, double x_mm);
/// ∫₀¹ β |∂²d/∂s²|² ds of 6.3 for the deflection of 6.2 with s = x/L and β = E I/(2L³):
/// F² L³ / (96 E I) (mJ), the exact bending energy of that beam.
double bending_energy_6_2(double F_N, double E_MPa, double I_mm4, double L_mm);

// ---- energy map (6.2–6.5) ------------------------------------------------------------------------

/// Per-element energies at an equilibrium (all vectors have one entry per element).
struct ElementEnergies {
  std::vector<double> stretch_mJ;    ///< α |∂d/∂s|² of 6.3: ½ f E A (l − L)²/L
  std::vector<double> bend_mJ;       ///< β |∂²d/∂s²|² of 6.3: the element's share of its two joints
  std::vector<double> local_mJ;      ///< 6.2–6.3: bending of the element under its own normal tissue force
  std::vector<double> external_mJ;   ///< 6.4 per element: −F_i·v_i (tissue force on the element · its displacement)
  std::vector<double> e_star_mJ;     ///< E*_i = stretch + bend + local + |external| (what drives 6.16)
  std::vector<double> density;       ///< E*_i / V_i in kJ/m³ (kEnergyDensityUnit)
  double total_potential_mJ = 0;     ///< 6.5 summed: the Π that the minimisation lowers
};

/// The energy map of state q with stiffness factors f under wound load F (N).
ElementEnergies element_energies(const ClipModel& m, const ClipState& q, const std::vector<double>& f, double load_N);

/// Advances 6.16 with the baseline term over Δt with E* held constant (exact solution of
/// ḋ = (1 − d)(k0 + √E*/τ_D)): returns 1 − (1 − d) exp(−(k0 + √E*/τ_D) Δt). E* in kJ/m³, τ_D in
/// week·(kJ/m³)^½ (converted with kTauTimeUnit_days), k0 in 1/day, Δt in days.
double advance_degradation(double d, double e_star_kJ_per_m3, double tau_d, double k0_per_day, double dt_days);

// ---- minimisation (6.8–6.13) --------------------------------------------------------------------

struct MinimiseOptions {
  double force_tolerance_N = 1e-8;   ///< stop when max |P| (the non-equilibrium force, N) is below this
  int max_iterations = 200;
  double armijo = 1e-4;              ///< sufficient-decrease constant of the backtracking line search
  int max_halvings = 60;
};

struct MinimiseRecord {
  bool converged = false;
  int iterations = 0;                  ///< accepted iterations
  int non_pd_shifts = 0;               ///< iterations where K was not positive definite and was shifted
  int steepest_descent_steps = 0;      ///< iterations where P·u ≤ 0 even after the shift (then u = P)
  double final_residual_N = 0;         ///< max |P| at the end
  std::vector<double> energy_mJ;       ///< Π before the first and after every accepted iteration
  std::vector<double> energy_change_mJ;///< ΔΠ of every accepted iteration (term by term, < 0)
  std::vector<double> residual_N;      ///< max |P| before the first and after every accepted iteration
  std::vector<double> p_dot_u;         ///< P·u of every accepted iteration (6.13, > 0)
};

/// Minimises Π over q (in place) for stiffness factors f and load F: solve K u = P with
/// K = ∇²Π, P = −∇Π (6.8–6.10); when K is not positive definite (LDLᵀ pivot ≤ 0) it is shifted by
/// μ diag|K| with μ growing tenfold until it is; the step is accepted only if P·u > 0 (6.13) and
/// a backtracking line search finds a sufficient decrease of Π (v ← v + s u, 6.11–6.12).
MinimiseRecord minimise_energy(const ClipModel& m, ClipState& q, const std::vector<double>& f, double load_N,
                               const MinimiseOptions& o = {});

// ---- degradation in time (6.14–6.16) ------------------------------------------------------------

struct DegradationOptions {
  double tau_d = 241.41;             ///< τ_D of 6.16 in week·(kJ/m³)^½ (Table 6.1, group 1)
  double load_N = 5.0;               ///< wound tension held by the clip (in vitro: 5 N thread, §6.3.2)
  double end_days = 28.0;            ///< 4 weeks
  double dt_days = 0.1;              ///< time step; E* is held constant over a step (exact update)
  std::vector<double> stage_days = {3.5, 7.0, 10.5, 14.0, 17.5};  ///< Fig. 6.8's 0.5 … 2.5 weeks
  int deployment_load_steps = 10;    ///< the load is raised in this many equal steps at deployment
  bool keep_stages = true;           ///< store the full state at t = 0 and at stage_days
  MinimiseOptions minimise;
};

/// Everything at one instant.
struct ClipSnapshot {
  double t_days = 0;
  ClipState q;
  std::vector<double> d;
  std::vector<bool> fractured;
  ElementEnergies energies;
  bool load_carried = true;
};

/// One row per time step (and one at t = 0).
struct DegradationStep {
  double t_days = 0;
  double mass_fraction = 1;
  int fractured = 0;
  bool load_carried = true;
  double potential_mJ = 0;
  double stored_mJ = 0;          ///< Σ E*_i over the clip
  int iterations = 0;
  double residual_N = 0;
};

struct DegradationResult {
  MinimiseRecord deployment;                 ///< the last load step of the deployment
  std::vector<MinimiseRecord> deployment_steps;
  ClipSnapshot initial;                      ///< deployed, before degradation (Fig. 6.3's map)
  std::vector<ClipSnapshot> stages;          ///< at DegradationOptions::stage_days
  std::vector<DegradationStep> steps;
  std::vector<double> fracture_day;          ///< per element, −1 when it never broke
  double load_released_day = -1;             ///< when the clip stopped holding the wound (−1: never)
  double max_displacement_mm = 0;            ///< at deployment
  double max_bending_stress_MPa = 0;         ///< at deployment (elastic; compare with the yield strength)
  int total_iterations = 0;
  bool all_converged = true;
  ClipSnapshot final_state;
};

/// Mass remaining: Σ L_e (1 − d_e) / Σ L_e (uniform section).
double mass_fraction(const ClipModel& m, const std::vector<double>& d);

/// Deploys the clip (load raised in steps, Π minimised at each), then integrates 6.16 with the
/// baseline term over [0, end_days]: per step, with E*_i from the current equilibrium,
///   1 − d_i(t + Δt) = (1 − d_i(t)) exp(−(k0 + √E*_i / τ_D) Δt),
/// marks elements whose d reaches the fracture threshold as broken (stiffness factor
/// fractured_stiffness_fraction), drops the load when no intact path joins the two legs' tissue
/// contacts any more, and re-minimises Π with α = α0(1 − d), β = β0(1 − d).
/// Throws UsageError for τ_D ≤ 0, negative load, dt ≤ 0 or end < 0.
DegradationResult simulate_degradation(const ClipModel& m, const DegradationOptions& o, Progress* progress = nullptr);

// ---- calibration of τ_D (Table 6.1) -------------------------------------------------------------

/// A measured mass-remaining series.
struct MassSeries {
  std::vector<double> t_days, mass_fraction;
  std::vector<int> line;                ///< source line of each row
  std::filesystem::path source;
};

/// Reads a CSV with header columns `t_days` and `mass_fraction` (any order, others ignored).
/// Throws CalibrationDataError (exit 21) naming file, line and column for: missing columns,
/// unparsable or non-finite numbers, t < 0, times not strictly increasing, mass_fraction outside
/// (0, 1 + max_increase], a mass that rises by more than `max_increase` (fraction of the initial
/// mass) from one row to a later one — a degradation series cannot gain mass beyond weighing
/// noise — and fewer than 2 rows after t = 0.
MassSeries read_mass_csv(const std::filesystem::path& path, double max_increase = 0.05);
MassSeries parse_mass_csv(const std::string& text, const std::filesystem::path& source, double max_increase = 0.05);

struct TauFitOptions {
  double tau_min = 10.0, tau_max = 1.0e5;   ///< search interval of τ_D
  int grid = 10;                            ///< log-spaced scan before the golden-section refinement
  double relative_tolerance = 1e-3;         ///< on log τ_D (≈ relative on τ_D)
  /// Minimise Σ((model − y)/y)² instead of Σ(model − y)²: the maximum-likelihood choice when the
  /// weighing error is proportional to the mass. R² and RMSE are reported unweighted either way.
  bool relative_residuals = false;
};

struct TauFit {
  double tau_d = 0;
  double sse = 0, r2 = 0, rmse = 0;          ///< of mass_fraction (fraction units)
  std::vector<double> predicted;             ///< model mass fraction at the series' times
  int evaluations = 0;                       ///< simulations run
  bool at_bound = false;                     ///< the optimum lies on the search interval's edge
};

/// Model mass fraction at `times` (linear interpolation between time steps), simulating to the
/// last time only.
std::vector<double> model_mass_at(const ClipModel& m, const DegradationOptions& o, const std::vector<double>& times);

/// Least-squares τ_D for `data` (the clip `m` under o.load_N; o.tau_d is ignored): log-spaced
/// scan, then golden-section search on log τ_D around the best point. Throws UsageError when the
/// model's mass curve does not depend on τ_D (no load: the strain energy is zero) or the bounds
/// are invalid.
TauFit fit_tau_d(const ClipModel& m, const DegradationOptions& o, const MassSeries& data, const TauFitOptions& fo = {},
                 Progress* progress = nullptr);

}  // namespace organsmith::physics
