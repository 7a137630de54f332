#pragma once
// Constitutive models of the thesis (ch. 2.2.2, 3, 4.1, 4.2, 5.1) with closed-form strain energy,
// the stress a test measures, and the derivative of that stress with respect to every parameter.
// The derivations, and where they depart from the printed equations, are in physics/README.md.
//
// Conventions: stretches are dimensionless (λ = current length / reference length); stresses are
// nominal (engineering, force per reference area) in Pa, which is what uniaxial tests record;
// the cutting model works in metres and newtons. Parameters are passed as flat arrays in the
// order of Model::parameters().

#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace organsmith::physics {

/// How a measurement was taken. For isotropic models the direction is irrelevant; the membrane
/// (Fung) models use it to pick the loaded axis.
enum class LoadCase {
  /// Uniaxial tension along the circumferential axis θ, the other in-plane axis stress-free.
  uniaxial_circumferential,
  /// Uniaxial tension along the longitudinal axis z, the other in-plane axis stress-free.
  uniaxial_longitudinal,
  /// Both in-plane stretches prescribed; the circumferential nominal stress is measured.
  biaxial_circumferential,
  /// Both in-plane stretches prescribed; the longitudinal nominal stress is measured.
  biaxial_longitudinal,
  /// Displacement-controlled cutting (kelvin-cutting): x is the blade displacement in metres.
  displacement,
};

/// One measurement point.
struct LoadPoint {
  /// Stretch along the loaded axis (1), or for LoadCase::displacement the blade displacement (m).
  double x = 1.0;
  /// Biaxial only: the prescribed stretch of the other in-plane axis (1).
  double lateral_stretch = 1.0;
  LoadCase load = LoadCase::uniaxial_circumferential;
};

/// Name, unit and default search interval of one parameter. The intervals are the GA's search box
/// when the user gives none; they bracket the thesis tables with margin (see each model's .cpp).
struct ParameterInfo {
  std::string name;
  std::string unit;
  double lower = 0.0;
  double upper = 1.0;
};

/// A constitutive (or force) law that a calibration can fit.
class Model {
 public:
  virtual ~Model() = default;
  /// Identifier used on the command line and in data/materials.toml ("fung-wall", …).
  virtual std::string_view name() const = 0;
  virtual const std::vector<ParameterInfo>& parameters() const = 0;
  std::size_t parameter_count() const { return parameters().size(); }

  /// The measured quantity (nominal stress in Pa, or force in N) at each point, written to `out`
  /// (same length as `points`). When `jacobian` is non-empty it receives ∂out_i/∂p_j row-major
  /// (points.size() × parameter_count()). Points where the law is undefined for `p` (e.g. the
  /// logarithm's argument leaves (0, ∞)) give NaN; callers treat NaN as an infeasible parameter set.
  virtual void respond(std::span<const LoadPoint> points, std::span<const double> p,
                       std::span<double> out, std::span<double> jacobian = {}) const = 0;

  /// Strain energy per reference volume (J/m³ = Pa) stored when the point's deformation is
  /// reached quasi-statically along the test's loading path (uniaxial: lateral axes at
  /// equilibrium). Its derivative with respect to the loaded stretch is the nominal stress that
  /// respond() returns; tests check this by finite differences. NaN for laws without an energy
  /// (the viscoelastic cutting model).
  virtual double energy(const LoadPoint& point, std::span<const double> p) const = 0;

  /// Convenience: one point, no Jacobian.
  double respond_one(const LoadPoint& point, std::span<const double> p) const;
};

/// Options that select a model variant.
struct ModelOptions {
  /// Number of Ogden terms N (parameters μ1, α1, …, μN, αN).
  int ogden_terms = 2;
  /// Bulk modulus K of the fung-organ volumetric energy (Pa); 39 kPa per thesis §5.1.5.
  double bulk_modulus_Pa = 39.0e3;
  /// Blade speed v of the kelvin-cutting law (m/s); 0.000193 m/s measured in thesis §4.2.5.
  double blade_speed_m_per_s = 0.000193;
};

/// The models known to organsmith, by name.
std::vector<std::string> model_names();

/// Creates model `name`. Throws organsmith::UsageError for an unknown name, listing the known ones.
std::unique_ptr<Model> make_model(std::string_view name, const ModelOptions& options = {});

// ---- Closed forms used by the models, exposed for tests and the haptic loop --------------------

/// Cauchy (true) stress from the nominal stress of an incompressible uniaxial test: the current
/// cross-section is A0/λ, so σ = λ T (thesis 5.1.16 read backwards). Pa.
inline double cauchy_from_nominal_uniaxial(double nominal_Pa, double stretch) { return stretch * nominal_Pa; }

/// Fung membrane energy W = c/2 (e^Q − 1) + W_vol with Q = a1 Eθ² + a2 Ez² + 2 a4 Eθ Ez and
/// W_vol = K t⁻² [(J−1)² + t (ln J)²]/4, J = λθ λz (thesis 5.1.3, 5.1.11, 5.1.13). Without
/// volumetric part pass K = 0 (t is then unused). Green strains E = (λ² − 1)/2. Pa.
struct FungParameters {
  double c_Pa = 0.0, a1 = 0.0, a2 = 0.0, a4 = 0.0;
  double t = 1.0;          ///< volumetric shape parameter (dimensionless)
  double bulk_Pa = 0.0;    ///< K; 0 for the wall model
};
double fung_energy(const FungParameters& f, double E_theta, double E_z);
/// Second-Piola–Kirchhoff (membrane) stresses S = ∂W/∂E, Pa.
void fung_pk2(const FungParameters& f, double E_theta, double E_z, double& S_theta, double& S_z);

/// Uniaxial membrane solve: the lateral Green strain at which the lateral stress vanishes for a
/// given loaded Green strain (`loaded_is_theta` selects the loaded axis). Closed form when K = 0,
/// safeguarded Newton otherwise. NaN when no physical root (λ_lateral > 0) exists.
double fung_lateral_strain(const FungParameters& f, double E_loaded, bool loaded_is_theta);

/// kelvin-cutting (thesis 4.2.8): F(u) = μ0 u (1 − e^(−u μ1/(v η1))), u in m, μ0 and μ1 in N/m,
/// η1 in N·s/m, v in m/s; F in N.
double kelvin_force_N(double u_m, double mu0_N_per_m, double mu1_N_per_m, double eta1_N_s_per_m,
                      double v_m_per_s);

/// Geometry of the cut specimen for the elastic modulus (thesis §4.2.5: L0 = 3 mm, A0 ≈ 36 mm²).
struct CuttingGeometry {
  double length_m = 3.0e-3;     ///< L0, compressed specimen length
  double area_m2 = 36.0e-6;     ///< A0, cross-section through which the force acts
};

/// Elastic modulus E(u) = μ0 L0 (1 − e^(−u μ1/(v η1))) / A0 (thesis 4.2.13), Pa.
double kelvin_modulus_Pa(double u_m, double mu0_N_per_m, double mu1_N_per_m,
                         double eta1_N_s_per_m, double v_m_per_s, const CuttingGeometry& g = {});

/// Inverse of kelvin_modulus_Pa (thesis 4.2.17): u(E) = −(v η1/μ1) ln(1 − E A0/(μ0 L0)), m.
/// Defined for 0 ≤ E < μ0 L0/A0; NaN outside.
double kelvin_displacement_m(double E_Pa, double mu0_N_per_m, double mu1_N_per_m,
                             double eta1_N_s_per_m, double v_m_per_s, const CuttingGeometry& g = {});

/// Uniaxial stress of the artery model exactly as typeset in thesis eqs 4.1.6–4.1.7, errors
/// included (denominator 1 − G/2 with G = C2 a − C3 b² + 2 C4 a b, factor 2 C1). Not used by any
/// model: kept so that tests can show which printed numbers were computed from it (Tables
/// 4.1.2/4.1.3, columns C1, C2, C4). Pa.
double artery_logpoly_stress_as_printed(double stretch, std::span<const double> C);

}  // namespace organsmith::physics
