// Over 400 lines: the clip model as one unit: its preset reader with every check, its geometry
// (thesis Fig. 6.x) and the beam elements assembled on it.
#include "physics/degradation/clip.h"
#include "core/format.h"

#include "clips_toml.h"  // generated from data/clips.toml
#include "core/errors.h"
#include "core/file_io.h"
#include "core/toml_parse.h"
#include "physics/materials/models.h"
#include "physics/materials/presets.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <set>
#include <sstream>

namespace organsmith::physics {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::string fmt(double v) { return format_g(v); }

/// Reads the tables of a clip preset, insisting that every key is known and present.
class PresetReader {
 public:
  PresetReader(const toml::table& root, std::filesystem::path source) : root_(root), source_(std::move(source)) {
    static const std::set<std::string> sections = {"clip", "shape", "tissue", "degradation"};
    for (const auto& [k, v] : root_) {
      const std::string key(k.str());
      if (!sections.count(key))
        fail("unknown section [" + key + "]", "the sections are [clip], [shape], [tissue] and [degradation]");
      if (!v.is_table()) fail("'" + key + "' must be a table ([" + key + "])");
    }
  }

  /// Declares the keys of `section`; unknown keys there are errors.
  void keys(const std::string& section, const std::set<std::string>& known) {
    const toml::table* t = root_[section].as_table();
    if (!t) fail("missing section [" + section + "]", "start from `organsmith degrade --print-clip`");
    for (const auto& [k, v] : *t)
      if (!known.count(std::string(k.str()))) {
        std::string list;
        for (const auto& n : known) list += (list.empty() ? "" : ", ") + n;
        fail("unknown key '" + section + "." + std::string(k.str()) + "' (line " +
                 std::to_string(v.source().begin.line) + ")",
             "known keys of [" + section + "]: " + list);
      }
  }

  double number(const std::string& section, const std::string& key) const {
    const toml::node* n = root_[section][key].node();
    if (!n) fail("missing key '" + section + "." + key + "'", "see data/clips.toml for every key with its meaning");
    if (auto v = n->value<double>()) {
      if (!std::isfinite(*v)) fail(where(*n, section, key) + " is not a finite number");
      return *v;
    }
    fail(where(*n, section, key) + " must be a number");
  }

  std::string text(const std::string& section, const std::string& key, bool required = true) const {
    const toml::node* n = root_[section][key].node();
    if (!n) {
      if (required) fail("missing key '" + section + "." + key + "'");
      return {};
    }
    if (auto v = n->value<std::string>()) return *v;
    fail(where(*n, section, key) + " must be a string");
  }

  std::array<double, 2> pair(const std::string& section, const std::string& key) const {
    const toml::node* n = root_[section][key].node();
    if (!n) fail("missing key '" + section + "." + key + "'");
    const toml::array* a = n->as_array();
    if (!a || a->size() != 2 || !(*a)[0].value<double>() || !(*a)[1].value<double>())
      fail(where(*n, section, key) + " must be two numbers [min, max]");
    return {*(*a)[0].value<double>(), *(*a)[1].value<double>()};
  }

  void check(bool ok, const std::string& section, const std::string& key, const std::string& what) const {
    if (ok) return;
    const toml::node* n = root_[section][key].node();
    fail((n ? where(*n, section, key) : "'" + section + "." + key + "'") + " " + what);
  }

  [[noreturn]] void fail(const std::string& message, const std::string& hint = {}) const {
    throw CaseFileError("clip preset: " + message, source_, hint.empty() ? "fix the value in the clip preset" : hint);
  }

 private:
  static std::string where(const toml::node& n, const std::string& section, const std::string& key) {
    return "'" + section + "." + key + "' (line " + std::to_string(n.source().begin.line) + ")";
  }
  const toml::table& root_;
  std::filesystem::path source_;
};

Eigen::Vector2d perp_over_norm2(const Eigen::Vector2d& v) {
  // ∇θ of the direction angle θ = atan2(v_y, v_x).
  return Eigen::Vector2d(-v.y(), v.x()) / v.squaredNorm();
}

Eigen::Matrix2d angle_hessian(const Eigen::Vector2d& v) {
  const double r4 = v.squaredNorm() * v.squaredNorm();
  Eigen::Matrix2d H;
  H << 2 * v.x() * v.y(), v.y() * v.y() - v.x() * v.x(), v.y() * v.y() - v.x() * v.x(), -2 * v.x() * v.y();
  return H / r4;
}

void add_block(std::vector<Eigen::Triplet<double>>& t, int r, int c, const Eigen::Matrix2d& m) {
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) t.emplace_back(r + i, c + j, m(i, j));
}

}  // namespace

// ---- preset -------------------------------------------------------------------------------------

const char* builtin_clip_preset_text() { return kClipsToml; }

ClipPreset parse_clip_preset(const std::string& text, const std::filesystem::path& source) {
  const toml::table root = parse_toml(text, source, "the clip preset", "the file must be TOML like data/clips.toml");
  PresetReader r(root, source);
  r.keys("clip", {"name", "source", "thickness_mm", "width_mm", "youngs_modulus_MPa", "poisson_ratio",
                  "yield_strength_MPa", "density_g_per_cm3"});
  r.keys("shape", {"crown_radius_mm", "leg_length_mm", "crown_height_mm", "elements"});
  r.keys("tissue", {"material", "block_mm", "engaged_depth_mm", "bearing_width_mm"});
  r.keys("degradation", {"baseline_rate_per_day", "fracture_threshold", "fractured_stiffness_fraction"});

  ClipPreset p;
  p.file = source;
  p.name = r.text("clip", "name");
  p.source = r.text("clip", "source", false);
  p.thickness_mm = r.number("clip", "thickness_mm");
  p.width_mm = r.number("clip", "width_mm");
  p.youngs_modulus_MPa = r.number("clip", "youngs_modulus_MPa");
  p.poisson_ratio = r.number("clip", "poisson_ratio");
  const auto y = r.pair("clip", "yield_strength_MPa");
  p.yield_min_MPa = y[0];
  p.yield_max_MPa = y[1];
  p.density_g_per_cm3 = r.number("clip", "density_g_per_cm3");
  p.crown_radius_mm = r.number("shape", "crown_radius_mm");
  p.leg_length_mm = r.number("shape", "leg_length_mm");
  p.crown_height_mm = r.number("shape", "crown_height_mm");
  const double elements = r.number("shape", "elements");
  p.tissue_material = r.text("tissue", "material");
  p.block_mm = r.number("tissue", "block_mm");
  p.engaged_depth_mm = r.number("tissue", "engaged_depth_mm");
  p.bearing_width_mm = r.number("tissue", "bearing_width_mm");
  p.baseline_rate_per_day = r.number("degradation", "baseline_rate_per_day");
  p.fracture_threshold = r.number("degradation", "fracture_threshold");
  p.fractured_stiffness_fraction = r.number("degradation", "fractured_stiffness_fraction");

  r.check(p.thickness_mm > 0, "clip", "thickness_mm", "must be positive");
  r.check(p.width_mm > 0, "clip", "width_mm", "must be positive");
  r.check(p.youngs_modulus_MPa > 0, "clip", "youngs_modulus_MPa", "must be positive");
  r.check(p.poisson_ratio >= 0 && p.poisson_ratio < 0.5, "clip", "poisson_ratio", "must lie in [0, 0.5)");
  r.check(p.yield_min_MPa > 0 && p.yield_min_MPa <= p.yield_max_MPa, "clip", "yield_strength_MPa",
          "must be [min, max] with 0 < min ≤ max");
  r.check(p.density_g_per_cm3 > 0, "clip", "density_g_per_cm3", "must be positive");
  r.check(p.crown_radius_mm > 0, "shape", "crown_radius_mm", "must be positive");
  r.check(p.leg_length_mm > 0, "shape", "leg_length_mm", "must be positive");
  r.check(p.crown_height_mm >= 0, "shape", "crown_height_mm",
          "must be ≥ 0: the crown sits on or above the tissue surface");
  r.check(elements == std::floor(elements) && elements >= 8 && elements <= 100000, "shape", "elements",
          "must be a whole number between 8 and 100000");
  p.elements = static_cast<int>(elements);
  r.check(p.block_mm > 0, "tissue", "block_mm", "must be positive");
  r.check(p.engaged_depth_mm > 0, "tissue", "engaged_depth_mm", "must be positive");
  r.check(p.bearing_width_mm > 0, "tissue", "bearing_width_mm", "must be positive");
  r.check(p.baseline_rate_per_day >= 0, "degradation", "baseline_rate_per_day", "must be ≥ 0");
  r.check(p.fracture_threshold > 0 && p.fracture_threshold < 1, "degradation", "fracture_threshold",
          "must lie in (0, 1)");
  r.check(p.fractured_stiffness_fraction > 0 && p.fractured_stiffness_fraction < 1e-2, "degradation",
          "fractured_stiffness_fraction", "must lie in (0, 0.01)");
  // The tissue preset must exist.
  const MaterialLibrary lib = builtin_material_library();
  bool found = false;
  std::string known;
  for (const auto& m : lib.materials) {
    found = found || m.id == p.tissue_material;
    if (m.material.model == "fung-organ" || m.material.model == "fung-wall") known += "\n  " + m.id;
  }
  if (!found) r.fail("tissue.material '" + p.tissue_material + "' is no preset of data/materials.toml",
                     "hyperelastic presets:" + known);
  // The legs must reach into the block and stay inside it.
  const double tip_y = p.crown_height_mm - p.leg_length_mm;
  if (tip_y >= 0)
    r.fail("the clip's legs miss the tissue: their tips end at y = " + fmt(tip_y) +
               " mm, on or above the tissue surface (y = 0)",
           "make shape.leg_length_mm (" + fmt(p.leg_length_mm) + ") longer than shape.crown_height_mm (" +
               fmt(p.crown_height_mm) + ")");
  if (p.crown_radius_mm >= p.block_mm / 2 || -tip_y >= p.block_mm)
    r.fail("the clip's legs miss the tissue: they leave the " + fmt(p.block_mm) + " mm block (legs at x = ±" +
               fmt(p.crown_radius_mm) + " mm, tips at y = " + fmt(tip_y) + " mm)",
           "use a smaller clip or a larger tissue.block_mm");
  return p;
}

ClipPreset read_clip_preset(const std::filesystem::path& path) {
  return parse_clip_preset(
      read_input_file(path, "the clip preset", ExitCode::case_file, "check the path given to --clip"), path);
}

ClipPreset builtin_clip_preset() { return parse_clip_preset(kClipsToml, "data/clips.toml (embedded)"); }

const char* region_name(ClipRegion r) {
  switch (r) {
    case ClipRegion::crown: return "crown";
    case ClipRegion::left_leg: return "left_leg";
    case ClipRegion::left_contact: return "left_contact";
    case ClipRegion::right_leg: return "right_leg";
    case ClipRegion::right_contact: return "right_contact";
  }
  return "?";
}

// ---- geometry -----------------------------------------------------------------------------------

double ClipGeometry::total_length_mm() const {
  double s = 0;
  for (double l : length_mm) s += l;
  return s;
}

ClipGeometry build_clip_geometry(const ClipPreset& p, int elements) {
  const int n = elements > 0 ? elements : p.elements;
  if (n < 8) throw UsageError("a clip needs at least 8 elements (got " + std::to_string(n) + ")");
  const double R = p.crown_radius_mm, leg = p.leg_length_mm, yc = p.crown_height_mm;
  const double arc = std::numbers::pi * R, S = 2 * leg + arc;
  auto point = [&](double s) -> Eigen::Vector2d {
    if (s <= leg) return {-R, yc - leg + s};
    if (s <= leg + arc) {
      const double th = std::numbers::pi - (s - leg) / R;
      return {R * std::cos(th), yc + R * std::sin(th)};
    }
    return {R, yc - (s - leg - arc)};
  };
  ClipGeometry g;
  for (int k = 0; k <= n; ++k) g.nodes_mm.push_back(point(S * k / n));
  g.nodes_mm.front() = {-R, yc - leg};
  g.nodes_mm.back() = {R, yc - leg};
  g.tributary_mm.assign(static_cast<std::size_t>(n + 1), 0.0);
  for (int e = 0; e < n; ++e) {
    const Eigen::Vector2d a = g.nodes_mm[e], b = g.nodes_mm[e + 1];
    const double L = (b - a).norm();
    g.length_mm.push_back(L);
    double below = 0;
    if (a.y() < 0 && b.y() < 0) below = L;
    else if (a.y() < 0 || b.y() < 0) below = L * std::max(-a.y(), -b.y()) / std::abs(a.y() - b.y());
    g.embedded_mm.push_back(below);
    // The embedded part is lumped onto the end nodes with the linear shape functions: a part of
    // fraction a next to one node gives it L(a − a²/2) and the other node L a²/2.
    const double frac = below / L;
    const double near = L * (frac - frac * frac / 2), far = L * frac * frac / 2;
    std::array<double, 2> part = {0.0, 0.0};
    if (a.y() < 0 && b.y() < 0) part = {L / 2, L / 2};
    else if (a.y() < 0) part = {near, far};
    else if (b.y() < 0) part = {far, near};
    g.element_tributary_mm.push_back(part);
    g.tributary_mm[e] += part[0];
    g.tributary_mm[e + 1] += part[1];
    const double s_mid = S * (e + 0.5) / n;
    const bool left = s_mid < S / 2;
    if (s_mid > leg && s_mid < leg + arc) g.region.push_back(ClipRegion::crown);
    else if (below > L / 2) g.region.push_back(left ? ClipRegion::left_contact : ClipRegion::right_contact);
    else g.region.push_back(left ? ClipRegion::left_leg : ClipRegion::right_leg);
  }
  for (int k = 0; k <= n; ++k) g.side.push_back(g.nodes_mm[k].x() <= 0 ? -1 : 1);
  g.turning_rad.assign(static_cast<std::size_t>(n + 1), 0.0);
  for (int k = 1; k < n; ++k) {
    const Eigen::Vector2d a = g.nodes_mm[k] - g.nodes_mm[k - 1], b = g.nodes_mm[k + 1] - g.nodes_mm[k];
    g.turning_rad[k] = std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
  }
  // Both legs must have at least one node inside the tissue at this resolution.
  for (int side : {-1, 1}) {
    double contact = 0;
    for (int k = 0; k <= n; ++k)
      if (g.side[k] == side) contact += g.tributary_mm[k];
    if (contact <= 0)
      throw CaseFileError("the clip's " + std::string(side < 0 ? "left" : "right") +
                              " leg misses the tissue: no part of it lies below the tissue surface",
                          p.file, "lengthen shape.leg_length_mm or lower shape.crown_height_mm");
  }
  return g;
}

// ---- tissue -------------------------------------------------------------------------------------

TissueFoundation::TissueFoundation(const std::string& material_id, double engaged_depth_mm, double bearing_width_mm)
    : material_(material_id), h_(engaged_depth_mm), b_(bearing_width_mm) {
  const MaterialLibrary lib = builtin_material_library();
  const MaterialPreset& preset = lib.find(material_id);
  const auto model = make_model(preset.material.model, model_options_for(preset));
  const auto params = parameter_values(*model, preset.material.parameters);
  const int count = static_cast<int>(std::lround((lmax_ - lmin_) / dl_)) + 1;
  for (int k = 0; k < count; ++k) {
    const LoadPoint pt{lmin_ + k * dl_, 1.0, LoadCase::uniaxial_circumferential};
    const double W = model->energy(pt, params) * 1e-6, T = model->respond_one(pt, params) * 1e-6;  // Pa → MPa
    if (!std::isfinite(W) || !std::isfinite(T)) {
      if (pt.x < 1.0) {  // keep only the defined range around λ = 1
        W_.clear();
        T_.clear();
        lmin_ = pt.x + dl_;
        continue;
      }
      break;
    }
    W_.push_back(W);
    T_.push_back(T);
  }
  lmax_ = lmin_ + (static_cast<double>(W_.size()) - 1) * dl_;
  if (W_.size() < 10 || lmin_ > 0.95 || lmax_ < 1.05)
    throw UsageError("tissue preset '" + material_id + "' has no usable uniaxial energy around λ = 1",
                     "choose a hyperelastic preset (fung-organ, fung-wall)");
  // Small-strain modulus dT/dλ at λ = 1 by central differences of the model itself.
  const LoadPoint lo{1.0 - 1e-4, 1.0, LoadCase::uniaxial_circumferential};
  const LoadPoint hi{1.0 + 1e-4, 1.0, LoadCase::uniaxial_circumferential};
  e0_MPa_ = (model->respond_one(hi, params) - model->respond_one(lo, params)) / 2e-4 * 1e-6;
}

double TissueFoundation::cubic(double lambda, double& T, double& dT) const {
  const double x = (lambda - lmin_) / dl_;
  const auto last = static_cast<double>(W_.size() - 1);
  if (!(x >= 0) || !(x <= last)) {
    T = dT = kInf;
    return kInf;
  }
  const std::size_t k = std::min(static_cast<std::size_t>(x), W_.size() - 2);
  const double u = x - static_cast<double>(k);
  const double w0 = W_[k], w1 = W_[k + 1], m0 = T_[k] * dl_, m1 = T_[k + 1] * dl_;
  // Cubic Hermite on [0, 1] in u: values w0, w1, slopes m0, m1 (per unit u).
  const double u2 = u * u, u3 = u2 * u;
  const double W = (2 * u3 - 3 * u2 + 1) * w0 + (u3 - 2 * u2 + u) * m0 + (-2 * u3 + 3 * u2) * w1 + (u3 - u2) * m1;
  const double dW = (6 * u2 - 6 * u) * w0 + (3 * u2 - 4 * u + 1) * m0 + (-6 * u2 + 6 * u) * w1 + (3 * u2 - 2 * u) * m1;
  const double d2W = (12 * u - 6) * w0 + (6 * u - 4) * m0 + (-12 * u + 6) * w1 + (6 * u - 2) * m1;
  T = dW / dl_;
  dT = d2W / (dl_ * dl_);
  return W;
}

double TissueFoundation::max_gap_mm() const { return h_ * std::min(1.0 - lmin_, lmax_ - 1.0); }

void TissueFoundation::evaluate(double r, double& psi, double& dpsi, double& d2psi) const {
  double Tp, dTp, Tm, dTm;
  const double Wp = cubic(1.0 + r / h_, Tp, dTp);
  const double Wm = cubic(1.0 - r / h_, Tm, dTm);
  if (!std::isfinite(Wp) || !std::isfinite(Wm)) {
    psi = dpsi = d2psi = kInf;
    return;
  }
  psi = b_ * h_ * (Wp + Wm);
  dpsi = b_ * (Tp - Tm);
  d2psi = b_ / h_ * (dTp + dTm);
}

// ---- the model ----------------------------------------------------------------------------------

ClipModel::ClipModel(const ClipPreset& preset, int elements)
    : preset_(preset),
      geo_(build_clip_geometry(preset, elements)),
      tissue_(preset.tissue_material, preset.engaged_depth_mm, preset.bearing_width_mm) {
  // The tissue on one side of the wound is held by the half block (all sides fixed): a column of
  // the block's cross-section and half its width.
  k_block_ = tissue_.small_strain_modulus_MPa() * preset.block_mm * preset.block_mm / (preset.block_mm / 2);
  for (int n = 0; n < geo_.nodes(); ++n)
    if (geo_.tributary_mm[n] > 0) contact_nodes_.push_back(n);
}

ClipState ClipModel::reference_state() const {
  ClipState q = ClipState::Zero(dofs());
  for (int n = 0; n < geo_.nodes(); ++n) q.segment<2>(2 * n) = geo_.nodes_mm[n];
  return q;
}

double ClipModel::alpha0(int e) const {
  return preset_.youngs_modulus_MPa * preset_.area_mm2() / (2 * geo_.length_mm[e]);
}

double ClipModel::beta0(int e) const {
  const double L = geo_.length_mm[e];
  return preset_.youngs_modulus_MPa * preset_.inertia_mm4() / (2 * L * L * L);
}

double ClipModel::joint_stiffness(int n, const std::vector<double>& f) const {
  const double ca = geo_.length_mm[n - 1] / (2 * f[n - 1]), cb = geo_.length_mm[n] / (2 * f[n]);
  return preset_.youngs_modulus_MPa * preset_.inertia_mm4() / (ca + cb);
}

double ClipModel::turning_angle(const ClipState& q, int n) const {
  const Eigen::Vector2d a = q.segment<2>(2 * n) - q.segment<2>(2 * n - 2);
  const Eigen::Vector2d b = q.segment<2>(2 * n + 2) - q.segment<2>(2 * n);
  return std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
}

Eigen::Vector2d ClipModel::tissue_force(const ClipState& q, int n) const {
  const double l = geo_.tributary_mm[n];
  if (l <= 0) return Eigen::Vector2d::Zero();
  const int side_dof = dofs() - 2 + (geo_.side[n] < 0 ? 0 : 1);
  const Eigen::Vector2d g = q.segment<2>(2 * n) - geo_.nodes_mm[n] - Eigen::Vector2d(q[side_dof], 0.0);
  const double r = g.norm();
  if (r == 0) return Eigen::Vector2d::Zero();
  double psi, dpsi, d2psi;
  tissue_.evaluate(r, psi, dpsi, d2psi);
  return -l * dpsi * g / r;
}

double ClipModel::energy(const ClipState& q, const std::vector<double>& f, double F, ClipEnergyTerms* terms) const {
  ClipEnergyTerms t;
  const int N = geo_.elements();
  const double EA = preset_.youngs_modulus_MPa * preset_.area_mm2();
  for (int e = 0; e < N; ++e) {
    const double L = geo_.length_mm[e];
    const double l = (q.segment<2>(2 * e + 2) - q.segment<2>(2 * e)).norm();
    t.stretch_mJ += 0.5 * f[e] * EA / L * (l - L) * (l - L);
  }
  for (int n = 1; n < N; ++n) {
    const double dphi = turning_angle(q, n) - geo_.turning_rad[n];
    t.bend_mJ += 0.5 * joint_stiffness(n, f) * dphi * dphi;
  }
  const int xl = dofs() - 2, xr = dofs() - 1;
  for (int n : contact_nodes_) {
    const int sd = geo_.side[n] < 0 ? xl : xr;
    const Eigen::Vector2d g = q.segment<2>(2 * n) - geo_.nodes_mm[n] - Eigen::Vector2d(q[sd], 0.0);
    double psi, dpsi, d2psi;
    tissue_.evaluate(g.norm(), psi, dpsi, d2psi);
    t.tissue_mJ += geo_.tributary_mm[n] * psi;
  }
  t.block_mJ = 0.5 * k_block_ * (q[xl] * q[xl] + q[xr] * q[xr]);
  t.load_mJ = F * q[xl] - F * q[xr];
  if (terms) *terms = t;
  return t.total();
}

double ClipModel::energy_change(const ClipState& q, const ClipState& u, const std::vector<double>& f, double F) const {
  const int N = geo_.elements();
  const double EA = preset_.youngs_modulus_MPa * preset_.area_mm2();
  double dE = 0;
  for (int e = 0; e < N; ++e) {
    const double L = geo_.length_mm[e];
    const Eigen::Vector2d a = q.segment<2>(2 * e + 2) - q.segment<2>(2 * e);
    const Eigen::Vector2d da = u.segment<2>(2 * e + 2) - u.segment<2>(2 * e);
    const double l = a.norm(), l1 = (a + da).norm();
    const double dl = da.dot(2 * a + da) / (l + l1);  // l1 − l without cancellation
    dE += 0.5 * f[e] * EA / L * dl * (l1 + l - 2 * L);
  }
  for (int n = 1; n < N; ++n) {
    const Eigen::Vector2d a = q.segment<2>(2 * n) - q.segment<2>(2 * n - 2);
    const Eigen::Vector2d b = q.segment<2>(2 * n + 2) - q.segment<2>(2 * n);
    const Eigen::Vector2d a1 = a + u.segment<2>(2 * n) - u.segment<2>(2 * n - 2);
    const Eigen::Vector2d b1 = b + u.segment<2>(2 * n + 2) - u.segment<2>(2 * n);
    // Rotation of each segment, then the change of the turning angle.
    const double ra = std::atan2(a.x() * a1.y() - a.y() * a1.x(), a.dot(a1));
    const double rb = std::atan2(b.x() * b1.y() - b.y() * b1.x(), b.dot(b1));
    const double phi = std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
    const double dphi = rb - ra;
    dE += 0.5 * joint_stiffness(n, f) * dphi * (2 * (phi - geo_.turning_rad[n]) + dphi);
  }
  const int xl = dofs() - 2, xr = dofs() - 1;
  for (int n : contact_nodes_) {
    const int sd = geo_.side[n] < 0 ? xl : xr;
    const Eigen::Vector2d g = q.segment<2>(2 * n) - geo_.nodes_mm[n] - Eigen::Vector2d(q[sd], 0.0);
    const Eigen::Vector2d g1 = g + u.segment<2>(2 * n) - Eigen::Vector2d(u[sd], 0.0);
    const double r0 = g.norm(), r1 = g1.norm();
    double p0, p1, d0, d1, dm, h2;
    tissue_.evaluate(r0, p0, d0, h2);
    tissue_.evaluate(r1, p1, d1, h2);
    if (!std::isfinite(p1)) return kInf;
    const Eigen::Vector2d dg = g1 - g;
    const double dr = r0 + r1 > 0 ? dg.dot(2 * g + dg) / (r0 + r1) : 0.0;  // r1 − r0 without cancellation
    if (std::abs(dr) < 1e-3 * preset_.engaged_depth_mm) {
      // ψ(r1) − ψ(r0) = ∫ψ'; Simpson's rule is exact on one cubic piece and avoids subtracting
      // two nearly equal energies when the step is tiny.
      double pm, hm;
      tissue_.evaluate(0.5 * (r0 + r1), pm, dm, hm);
      dE += geo_.tributary_mm[n] * dr / 6 * (d0 + 4 * dm + d1);
    } else {
      dE += geo_.tributary_mm[n] * (p1 - p0);
    }
  }
  dE += 0.5 * k_block_ * (u[xl] * (2 * q[xl] + u[xl]) + u[xr] * (2 * q[xr] + u[xr]));
  dE += F * u[xl] - F * u[xr];
  return dE;
}

void ClipModel::gradient_hessian(const ClipState& q, const std::vector<double>& f, double F, Eigen::VectorXd& grad,
                                 Eigen::SparseMatrix<double>* hessian) const {
  const int N = geo_.elements(), D = dofs();
  const double EA = preset_.youngs_modulus_MPa * preset_.area_mm2();
  grad = Eigen::VectorXd::Zero(D);
  std::vector<Eigen::Triplet<double>> trip;
  if (hessian) trip.reserve(static_cast<std::size_t>(16 * N + 36 * N + 9 * contact_nodes_.size() + 2));
  // Stretching: ½ k (l − L)².
  for (int e = 0; e < N; ++e) {
    const double L = geo_.length_mm[e], k = f[e] * EA / L;
    const Eigen::Vector2d a = q.segment<2>(2 * e + 2) - q.segment<2>(2 * e);
    const double l = a.norm();
    const Eigen::Vector2d dir = a / l;
    const Eigen::Vector2d g = k * (l - L) * dir;
    grad.segment<2>(2 * e) -= g;
    grad.segment<2>(2 * e + 2) += g;
    if (hessian) {
      const Eigen::Matrix2d P = dir * dir.transpose();
      const Eigen::Matrix2d H = k * (P + (l - L) / l * (Eigen::Matrix2d::Identity() - P));
      add_block(trip, 2 * e, 2 * e, H);
      add_block(trip, 2 * e + 2, 2 * e + 2, H);
      add_block(trip, 2 * e, 2 * e + 2, -H);
      add_block(trip, 2 * e + 2, 2 * e, -H);
    }
  }
  // Bending: ½ k (φ − φ0)², φ = θ(b) − θ(a), a = x_n − x_{n−1}, b = x_{n+1} − x_n.
  for (int n = 1; n < N; ++n) {
    const double k = joint_stiffness(n, f);
    const Eigen::Vector2d a = q.segment<2>(2 * n) - q.segment<2>(2 * n - 2);
    const Eigen::Vector2d b = q.segment<2>(2 * n + 2) - q.segment<2>(2 * n);
    const double phi = std::atan2(a.x() * b.y() - a.y() * b.x(), a.dot(b));
    const double m = k * (phi - geo_.turning_rad[n]);
    const Eigen::Vector2d ta = perp_over_norm2(a), tb = perp_over_norm2(b);
    // ∂φ/∂x_{n−1} = ta, ∂φ/∂x_n = −ta − tb, ∂φ/∂x_{n+1} = tb.
    const Eigen::Vector2d gp[3] = {ta, -ta - tb, tb};
    for (int i = 0; i < 3; ++i) grad.segment<2>(2 * (n - 1 + i)) += m * gp[i];
    if (hessian) {
      const Eigen::Matrix2d Ha = angle_hessian(a), Hb = angle_hessian(b);
      // ∇²φ: +Hb on (x_n, x_{n+1}) pattern [[H, −H], [−H, H]], −Ha on (x_{n−1}, x_n).
      Eigen::Matrix2d Hphi[3][3];
      Hphi[0][0] = -Ha;
      Hphi[0][1] = Ha;
      Hphi[1][0] = Ha;
      Hphi[1][1] = -Ha + Hb;
      Hphi[1][2] = -Hb;
      Hphi[2][1] = -Hb;
      Hphi[2][2] = Hb;
      Hphi[0][2] = Hphi[2][0] = Eigen::Matrix2d::Zero();
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          add_block(trip, 2 * (n - 1 + i), 2 * (n - 1 + j), k * gp[i] * gp[j].transpose() + m * Hphi[i][j]);
    }
  }
  // Tissue foundation: ℓ ψ(|g|), g = x_n − X_n − X_side e_x.
  const int xl = D - 2, xr = D - 1;
  for (int n : contact_nodes_) {
    const int sd = geo_.side[n] < 0 ? xl : xr;
    const double l = geo_.tributary_mm[n];
    const Eigen::Vector2d g = q.segment<2>(2 * n) - geo_.nodes_mm[n] - Eigen::Vector2d(q[sd], 0.0);
    const double r = g.norm();
    double psi, dpsi, d2psi;
    tissue_.evaluate(r, psi, dpsi, d2psi);
    Eigen::Matrix2d Hg;
    Eigen::Vector2d gg = Eigen::Vector2d::Zero();
    if (r > 1e-12) {
      const Eigen::Vector2d dir = g / r;
      gg = l * dpsi * dir;
      const Eigen::Matrix2d P = dir * dir.transpose();
      Hg = l * (d2psi * P + dpsi / r * (Eigen::Matrix2d::Identity() - P));
    } else {
      Hg = l * d2psi * Eigen::Matrix2d::Identity();  // ψ'(r)/r → ψ''(0)
    }
    grad.segment<2>(2 * n) += gg;
    grad[sd] -= gg.x();
    if (hessian) {
      add_block(trip, 2 * n, 2 * n, Hg);
      for (int i = 0; i < 2; ++i) {
        trip.emplace_back(2 * n + i, sd, -Hg(i, 0));
        trip.emplace_back(sd, 2 * n + i, -Hg(0, i));
      }
      trip.emplace_back(sd, sd, Hg(0, 0));
    }
  }
  grad[xl] += k_block_ * q[xl] + F;
  grad[xr] += k_block_ * q[xr] - F;
  if (hessian) {
    trip.emplace_back(xl, xl, k_block_);
    trip.emplace_back(xr, xr, k_block_);
    hessian->resize(D, D);
    hessian->setFromTriplets(trip.begin(), trip.end());
  }
}

}  // namespace organsmith::physics
