#pragma once
// The bioresorbable magnesium micro-clip of thesis chapter 6 closed onto a wound in a tissue block:
// the preset (data/clips.toml), the discretised centroid curve, the hyperelastic tissue foundation
// and the total potential energy of clip + tissue + wound load (thesis 6.1, 6.3–6.5) with its
// gradient and Hessian. The model and every departure from the print are in physics/degradation/DEGRADATION.md.
//
// Frame and units: millimetres, newtons, millijoules (N·mm), days. x runs across the wound (the
// incision is the plane x = 0), y is normal to the tissue surface and points out of the tissue
// (surface y = 0, tissue y < 0), the clip lies in the plane z = 0. Nodes are numbered from the left
// leg's tip, up the left leg, over the crown and down to the right leg's tip.

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <array>
#include <filesystem>
#include <string>
#include <vector>

namespace organsmith::physics {

/// A clip, its tissue and its degradation constants. Defaults are data/clips.toml's values.
struct ClipPreset {
  std::string name = "mg-microclip";
  std::string source;
  std::filesystem::path file;              ///< where the preset was read from (for messages)
  // Section and material (thesis §6.2.1, Fig. 6.4).
  double thickness_mm = 0.25;              ///< out of plane (z)
  double width_mm = 0.45;                  ///< in plane: the bending depth of the strip
  double youngs_modulus_MPa = 45000.0;
  double poisson_ratio = 0.35;
  double yield_min_MPa = 80.0, yield_max_MPa = 100.0;
  double density_g_per_cm3 = 1.74;
  // Shape of the deployed, stress-free clip.
  double crown_radius_mm = 1.5;            ///< semicircular crown; the legs stand 2 R apart
  double leg_length_mm = 2.5;              ///< straight legs below the crown's ends
  double crown_height_mm = 0.5;            ///< height of the crown's ends above the tissue surface
  int elements = 100;                      ///< beam elements along the centroid curve
  // Tissue (thesis §6.2.1: 30 mm cube, all sides fixed, hyperelastic).
  std::string tissue_material = "fung-organ/table-5.1.2/mean";
  double block_mm = 30.0;
  double engaged_depth_mm = 1.0;           ///< h: tissue layer strained by a leg's sideways motion
  double bearing_width_mm = 0.75;          ///< b: tissue width a leg bears on
  // Degradation (thesis 6.14–6.16 plus the baseline term of DEGRADATION.md).
  double baseline_rate_per_day = 0.025;    ///< k0: free corrosion rate of an unloaded clip, 1/day
  double fracture_threshold = 0.99;        ///< an element breaks when d reaches this
  double fractured_stiffness_fraction = 1e-6;

  double area_mm2() const { return thickness_mm * width_mm; }
  /// Second moment of area for in-plane bending, t w³/12 (mm⁴).
  double inertia_mm4() const { return thickness_mm * width_mm * width_mm * width_mm / 12.0; }
};

/// Parses a clip preset (format of data/clips.toml). Throws CaseFileError naming `source`, the
/// key and what is wrong for malformed TOML, unknown keys, non-positive or inconsistent values, and
/// a shape whose legs do not reach into the tissue or leave the block.
ClipPreset parse_clip_preset(const std::string& toml_text, const std::filesystem::path& source);
/// Reads a preset file; InputError (exit 3) when it cannot be read, else as parse_clip_preset.
ClipPreset read_clip_preset(const std::filesystem::path& path);
/// The preset embedded from data/clips.toml.
ClipPreset builtin_clip_preset();
/// The embedded text of data/clips.toml.
const char* builtin_clip_preset_text();

/// Parts of the clip (per element), as Fig. 6.3 names them.
enum class ClipRegion : int {
  crown = 0,
  left_leg = 1,          ///< left leg above the tissue surface
  left_contact = 2,      ///< left leg inside the tissue (contact zone)
  right_leg = 3,
  right_contact = 4,
};
const char* region_name(ClipRegion r);

/// The discretised centroid curve in its stress-free (deployed, unloaded) shape.
struct ClipGeometry {
  std::vector<Eigen::Vector2d> nodes_mm;   ///< N + 1 points
  std::vector<double> length_mm;           ///< per element, reference length L_e
  std::vector<double> turning_rad;         ///< per node: reference turning angle φ0 (0 at the two tips)
  std::vector<ClipRegion> region;          ///< per element
  std::vector<double> embedded_mm;         ///< per element: length below the tissue surface
  std::vector<double> tributary_mm;        ///< per node: embedded length it represents (0 above the tissue)
  /// per element: the embedded length it lumps onto its first and second node (sums to embedded_mm)
  std::vector<std::array<double, 2>> element_tributary_mm;
  std::vector<int> side;                   ///< per node: −1 left of the wound, +1 right (x = 0 counts as left)
  int elements() const { return static_cast<int>(length_mm.size()); }
  int nodes() const { return static_cast<int>(nodes_mm.size()); }
  double total_length_mm() const;
};

/// Builds the centroid curve of `p` with `elements` elements of equal reference length (0 = the
/// preset's count). Throws CaseFileError (naming p.file) when the legs miss the tissue.
ClipGeometry build_clip_geometry(const ClipPreset& p, int elements = 0);

/// The tissue's resistance to a leg node moving by g relative to the tissue around it, derived from
/// the uniaxial strain energy W(λ) of a hyperelastic preset: the layer of depth h in front of the
/// leg is compressed (λ = 1 − |g|/h) and the one behind it stretched (λ = 1 + |g|/h), each over the
/// bearing width b and the node's tributary length ℓ:
///     ψ(r) = ℓ b h [W(1 + r/h) + W(1 − r/h)],   r = |g|   (mJ).
/// W is tabulated from the model once and interpolated by C¹ cubic Hermite pieces whose slopes
/// are the model's nominal stress, so ψ, ψ' and ψ'' are mutually consistent.
class TissueFoundation {
 public:
  TissueFoundation() = default;
  /// Builds the table for material preset `material_id` of data/materials.toml.
  TissueFoundation(const std::string& material_id, double engaged_depth_mm, double bearing_width_mm);

  /// ψ(r), ψ'(r) (N) and ψ''(r) (N/mm) per unit tributary length (multiply by ℓ). Energy is +∞
  /// outside the tabulated stretch range (the tissue crushed or torn) so that line searches back off.
  void evaluate(double r_mm, double& psi_mJ_per_mm, double& dpsi_N_per_mm, double& d2psi_N_per_mm2) const;
  /// Small-strain Young's modulus of the uniaxial law, dT/dλ at λ = 1 (MPa).
  double small_strain_modulus_MPa() const { return e0_MPa_; }
  double max_gap_mm() const;    ///< largest |g| inside the tabulated range
  const std::string& material() const { return material_; }

 private:
  double cubic(double lambda, double& T, double& dT) const;  // W, T = W', dT = W'' (MPa)
  std::string material_;
  double h_ = 1.0, b_ = 0.75;
  double lmin_ = 0.1, lmax_ = 2.0, dl_ = 1e-3;
  std::vector<double> W_, T_;   // MPa (N/mm²), at λ = lmin + k dl
  double e0_MPa_ = 0.0;
};

/// Unknowns: node positions (x0, y0, x1, y1, …) in mm, then the sideways displacement of the
/// tissue on the left and on the right of the wound (X_L, X_R; mm).
using ClipState = Eigen::VectorXd;

/// Per-term breakdown of the potential at a state.
struct ClipEnergyTerms {
  double stretch_mJ = 0, bend_mJ = 0, tissue_mJ = 0, block_mJ = 0, load_mJ = 0;
  double total() const { return stretch_mJ + bend_mJ + tissue_mJ + block_mJ + load_mJ; }
};

/// The clip on its wound: total potential Π(q) = Σ stretching + Σ bending (6.3, α and β per element
/// scaled by the stiffness factor f_e = 1 − d_e, 6.14–6.15) + tissue foundation + block
/// + load potential (6.4: the wound tension F pulls the tissue on each side away from the wound).
class ClipModel {
 public:
  ClipModel(const ClipPreset& preset, int elements = 0);

  const ClipPreset& preset() const { return preset_; }
  const ClipGeometry& geometry() const { return geo_; }
  const TissueFoundation& tissue() const { return tissue_; }
  int dofs() const { return 2 * geo_.nodes() + 2; }
  /// The stress-free state (nodes at the reference shape, tissue not displaced).
  ClipState reference_state() const;

  /// α0 = E A / (2 L_e) (N/mm) and β0 = E I / (2 L_e³) (N/mm) of element e: with s = x/L the
  /// energies α|∂d/∂s|² and β|∂²d/∂s²|² of 6.3 then equal the beam's ½EA ε² and ½EI κ².
  double alpha0(int e) const;
  double beta0(int e) const;
  /// Stiffness of the wound side of the block (N/mm): small-strain modulus × 30 × 30 mm face / 15 mm.
  double block_stiffness_N_per_mm() const { return k_block_; }

  /// Π at q for stiffness factors f (per element, in (0, 1]) and wound load F (N). +∞ when a
  /// tissue gap leaves the foundation's range.
  double energy(const ClipState& q, const std::vector<double>& f, double load_N, ClipEnergyTerms* terms = nullptr) const;
  /// Π(q + u) − Π(q), evaluated term by term so that it stays accurate when it is tiny compared
  /// with Π (the descent check near convergence).
  double energy_change(const ClipState& q, const ClipState& u, const std::vector<double>& f, double load_N) const;
  /// ∇Π (N) into `grad` and, when `hessian` is not null, ∇²Π (N/mm; rotations handled exactly).
  void gradient_hessian(const ClipState& q, const std::vector<double>& f, double load_N, Eigen::VectorXd& grad,
                        Eigen::SparseMatrix<double>* hessian) const;

  /// Bending stiffness of the joint at interior node n (N·mm/rad): the two half-elements meeting
  /// there act in series, k = E I / (L_a/(2 f_a) + L_b/(2 f_b)).
  double joint_stiffness(int n, const std::vector<double>& f) const;
  /// Turning angle at interior node n in state q (rad).
  double turning_angle(const ClipState& q, int n) const;
  /// Force of the tissue on node n (N), zero above the surface.
  Eigen::Vector2d tissue_force(const ClipState& q, int n) const;

 private:
  ClipPreset preset_;
  ClipGeometry geo_;
  TissueFoundation tissue_;
  double k_block_ = 0.0;
  std::vector<int> contact_nodes_;
};

}  // namespace organsmith::physics
