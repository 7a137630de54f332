// The synthetic torso phantom (data/phantom.md). Over 400 lines for a reason: it is one geometric
// model of the anatomy (body, spine, lungs, airway tree, liver, gallbladder and their tissues),
// whose parts share one set of dimensions and one tissue lookup per voxel.

#include "pipeline/phantom/phantom.h"

#include "core/errors.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <vector>

// How the phantom is laid out (data/phantom.md lists the anatomy with its HU values).
//
// The anatomy is written in a "canonical" frame: x and y are LPS millimetres (x toward the
// patient's left, y toward posterior, the trunk centred on x = y = 0) and d is the depth in mm
// below the most cranial slice (d = 0 at the top, the neck). The canonical torso is 400 mm
// long: neck 0–70, lung apices at 70, carina at ~170, diaphragm domes at 268 (right) and 283
// (left), liver below the right dome, gallbladder from d ≈ 315 to 380, anterior.
//
// A volume of extent ≥ 400 mm shows the anatomy at true size, anchored at the top, and simply
// extends further into the abdomen below (kidneys, bowel, spine). A shorter volume compresses
// the canonical anatomy along z by extent/400, so that every organ (and its seed) is present
// for any extent: tests and previews then still see all four organs.
//
// The grid's top slice lies at z = 0 and slice k at z = -(n - 1 - k) · slice_mm, so the whole
// volume has z ≤ 0; x and y are centred on the trunk.

namespace organsmith {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kCanonicalLength_mm = 400.0;
constexpr const char* kTask = "synthesizing phantom";

// Unenhanced CT numbers, HU. Fat is one value everywhere so that "fat" is a single class.
namespace hu {
constexpr float air = -1000.0f;
constexpr float lung = -850.0f;
constexpr float fat = -100.0f;
constexpr float skin = 30.0f;
constexpr float muscle = 45.0f;
constexpr float soft_tissue = 40.0f;  // neck viscera, esophagus
constexpr float airway_wall = 50.0f;  // mucosa and cartilage rings, unresolved
constexpr float blood = 40.0f;        // heart and great vessels without contrast
constexpr float thyroid = 90.0f;      // iodine makes it brighter than muscle
constexpr float liver = 60.0f;
constexpr float bile = 10.0f;
constexpr float spleen = 50.0f;
constexpr float kidney = 30.0f;
constexpr float gastric_fluid = 15.0f;
constexpr float bowel = 25.0f;
constexpr float csf = 20.0f;
constexpr float disc = 90.0f;
constexpr float cartilage = 120.0f;  // costal cartilage
constexpr float cancellous = 350.0f;
constexpr float compact = 600.0f;  // thin bones where cortex and marrow are not resolved
constexpr float cortical = 1000.0f;
constexpr float min = -1024.0f;  // the range of a 12-bit CT stored as int16 with intercept −1024
constexpr float max = 3071.0f;
}  // namespace hu

struct Tissue {
  float hu;
  PhantomLabel label;
};

constexpr Tissue kAir{hu::air, PhantomLabel::background};
inline Tissue body(float value) { return {value, PhantomLabel::body}; }

double sq(double v) { return v * v; }
double lerp(double a, double b, double t) { return a + (b - a) * t; }
double clamp01(double v) { return std::clamp(v, 0.0, 1.0); }
double smoothstep(double e0, double e1, double v) {
  const double t = clamp01((v - e0) / (e1 - e0));
  return t * t * (3.0 - 2.0 * t);
}

// ---------------------------------------------------------------------------------------------
// Random numbers. std::normal_distribution is implementation-defined, so the phantom carries
// its own generator: splitmix64 streams, one per slice, seeded from (seed, slice), which makes
// the noise independent of how TBB splits the work.

std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() { return mix64(state_ += 0x9E3779B97F4A7C15ULL); }
  /// Uniform in [0, 1) with 53 random bits.
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }
  /// Uniform in [lo, hi).
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

 private:
  std::uint64_t state_;
};

/// Standard normal deviates by Marsaglia and Tsang's ziggurat with 128 layers: 99 % of draws
/// cost one table look-up and one comparison, which matters at tens of millions of voxels.
/// The layer index and the magnitude come from disjoint bits of one 64-bit draw.
class Ziggurat {
 public:
  Ziggurat() {
    constexpr double m = 2147483648.0;  // magnitudes are signed 32-bit integers
    double dn = kR, tn = kR;
    const double q = kV / std::exp(-0.5 * dn * dn);
    k_[0] = std::uint32_t(dn / q * m);
    k_[1] = 0;
    w_[0] = q / m;
    w_[127] = dn / m;
    f_[0] = 1.0;
    f_[127] = std::exp(-0.5 * dn * dn);
    for (int i = 126; i >= 1; --i) {
      dn = std::sqrt(-2.0 * std::log(kV / dn + std::exp(-0.5 * dn * dn)));
      k_[std::size_t(i + 1)] = std::uint32_t(dn / tn * m);
      tn = dn;
      f_[std::size_t(i)] = std::exp(-0.5 * dn * dn);
      w_[std::size_t(i)] = dn / m;
    }
  }

  double draw(SplitMix64& rng) const {
    for (;;) {
      const std::uint64_t bits = rng.next();
      const std::size_t layer = std::size_t(bits & 127u);
      const std::int64_t h = std::int32_t(std::uint32_t(bits >> 32));
      const double x = double(h) * w_[layer];
      if (std::uint64_t(h < 0 ? -h : h) < k_[layer]) return x;
      if (layer == 0) return tail(rng, h > 0);
      if (f_[layer] + rng.uniform() * (f_[layer - 1] - f_[layer]) < std::exp(-0.5 * x * x))
        return x;
    }
  }

 private:
  static constexpr double kR = 3.442619855899;       // start of the tail
  static constexpr double kV = 9.91256303526217e-3;  // area of each layer
  double tail(SplitMix64& rng, bool positive) const {
    double x, y;
    do {
      x = -std::log(1.0 - rng.uniform()) / kR;
      y = -std::log(1.0 - rng.uniform());
    } while (y + y < x * x);
    return positive ? kR + x : -kR - x;
  }
  std::array<std::uint32_t, 128> k_{};
  std::array<double, 128> w_{}, f_{};
};

// ---------------------------------------------------------------------------------------------
// Shape primitives in the canonical frame.

struct V3 {
  double x, y, d;  ///< LPS x, y in mm; depth below the top slice in canonical mm
};
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.d + b.d}; }
V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.d - b.d}; }
V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.d}; }
double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.d * b.d; }
double norm(V3 a) { return std::sqrt(dot(a, a)); }
V3 normalized(V3 a) { return (1.0 / norm(a)) * a; }

/// A tube along a segment whose radius varies linearly from `ra` at `a` to `rb` at `b`, with
/// round caps: vessels, bronchi, clavicles.
struct Tube {
  V3 a, b;
  double ra, rb;

  /// Distance outside the tube surface (negative inside), mm. Measured from the nearest axis
  /// point, which is exact for constant radius and close enough for the gentle tapers used.
  double excess(V3 p) const {
    const V3 ab = b - a;
    const double s = clamp01(dot(p - a, ab) / dot(ab, ab));
    return norm(p - (a + s * ab)) - lerp(ra, rb, s);
  }
  double d_min() const { return std::min(a.d - ra, b.d - rb); }
  double d_max() const { return std::max(a.d + ra, b.d + rb); }
};

/// An ellipsoid whose first two axes may be rotated in the axial plane. Its "level" q is 1 on
/// the surface; a margin of m mm outside it is roughly q < (1 + m / radius)².
struct Ellipsoid {
  V3 c{0.0, 0.0, 0.0};
  double rx = 1.0, ry = 1.0, rd = 1.0;

  Ellipsoid() = default;
  /// `angle_rad` rotates the x axis toward +y.
  Ellipsoid(V3 centre, double rx_mm, double ry_mm, double rd_mm, double angle_rad = 0.0)
      : c(centre),
        rx(rx_mm),
        ry(ry_mm),
        rd(rd_mm),
        cos_(std::cos(angle_rad)),
        sin_(std::sin(angle_rad)) {}

  double q_depth(double d) const { return sq((d - c.d) / rd); }
  double q_plane(double x, double y) const {
    const double dx = x - c.x, dy = y - c.y;
    return sq((dx * cos_ + dy * sin_) / rx) + sq((-dx * sin_ + dy * cos_) / ry);
  }

 private:
  double cos_ = 1.0, sin_ = 0.0;  // cached: q_plane runs for millions of voxels
};

/// Half width at row offset v of the superellipse |x/a|^n + |v/b|^n = 1 (−1 when the row
/// misses it). Trunk layers are nested superellipses, so per row each layer is an x interval.
double superellipse_half_width(double a, double b, double n, double v) {
  const double t = std::abs(v) / b;
  if (a <= 0.0 || t >= 1.0) return -1.0;
  return a * std::pow(1.0 - std::pow(t, n), 1.0 / n);
}

// ---------------------------------------------------------------------------------------------
// The anatomy: constants in the canonical frame, a few of them varied slightly by the seed.

struct Rib {
  double d_posterior;  ///< depth where the rib leaves the spine, mm
  double drop_mm;      ///< how much lower its anterior end lies
  double theta_bone;   ///< angle (0 posterior, π anterior) where bone turns into cartilage
  bool cartilage;      ///< whether costal cartilage continues to the sternum
};

struct Anatomy {
  // Airway.
  double carina_d = 170.0;
  double trachea_lumen_r = 8.5;  // 17 mm lumen
  double trachea_wall = 2.5;
  double trachea_sway_phase = 0.0;
  double bronchus_wall = 1.8;
  std::array<Tube, 6> bronchi{};  // lumen radii
  /// Depth where the main bronchi's lumens part in the axial slice: the true carina (the lumen
  /// divides there). Air above it is trachea (label 2), below it bronchus (lungs, label 4).
  double divide_d = 170.0;

  // Lungs and diaphragm.
  double apex_d = 70.0;
  double apex_dome_mm = 75.0;  // the apex is the top of an ellipsoidal cap this tall
  V3 dome_right{-65.0, -5.0, 268.0};
  V3 dome_left{65.0, -5.0, 283.0};
  V3 central_tendon{15.0, -35.0, 290.0};  // under the heart
  double diaphragm_mm = 5.0;

  // Mediastinum and vessels.
  Ellipsoid heart{V3{22.0, -32.0, 232.0}, 62.0, 44.0, 55.0, 0.45};
  std::array<Tube, 7> aorta{};
  Tube ivc{{-24.0, 20.0, 285.0}, {-22.0, 22.0, 900.0}, 11.0, 11.0};
  std::array<Tube, 4> clavicles{};
  std::array<Ellipsoid, 2> thyroid{};

  // Abdomen.
  V3 gb_neck{-20.0, -15.0, 320.0};
  V3 gb_axis{};             // unit vector from the neck toward the fundus
  V3 gb_bed{};              // unit vector perpendicular to the axis, toward the liver
  double gb_length = 80.0;  // tip to tip
  double gb_r_neck = 6.0;
  double gb_r_fundus = 15.0;
  Ellipsoid stomach{V3{72.0, -8.0, 335.0}, 46.0, 40.0, 50.0, 0.3};
  Ellipsoid spleen{V3{98.0, 52.0, 318.0}, 26.0, 42.0, 48.0, -0.5};
  std::array<Ellipsoid, 2> kidneys{};

  // Skeleton.
  std::array<Rib, 12> ribs{};
  double vertebra_period = 24.0;  // body + disc
  double disc_mm = 5.0;

  double gb_centre_distance() const { return gb_length - gb_r_neck - gb_r_fundus; }
  double gb_radius(double s01) const {
    // Pear: the radius rises quickly from the neck and is flat at the fundus, so the fundus
    // cap joins smoothly.
    return lerp(gb_r_neck, gb_r_fundus, 1.0 - sq(1.0 - s01));
  }
};

/// Trachea centreline at depth d: anterior in the neck, sinking posteriorly to the carina,
/// with a few millimetres of smooth sway.
std::array<double, 2> trachea_centre(const Anatomy& a, double d) {
  const double x = 3.0 * std::sin(2.0 * kPi * d / 260.0 + a.trachea_sway_phase);
  const double y = -24.0 + 24.0 * smoothstep(0.0, a.carina_d, d) +
                   2.0 * std::sin(2.0 * kPi * d / 180.0 + 0.5 * a.trachea_sway_phase);
  return {x, y};
}

Anatomy make_anatomy(std::uint64_t seed) {
  Anatomy a;
  // Small, bounded variations so different seeds give different cases while every size stays
  // within the published ranges of the product spec.
  SplitMix64 rng(mix64(seed ^ 0xA5A7F0C0DE5EEDULL));
  a.carina_d += rng.uniform(-5.0, 5.0);
  a.trachea_sway_phase = rng.uniform(0.0, 2.0 * kPi);
  a.gb_length += rng.uniform(-4.0, 4.0);
  a.gb_r_fundus += rng.uniform(-1.0, 1.0);

  const auto [cx, cy] = trachea_centre(a, a.carina_d);
  const V3 root{cx, cy, a.carina_d - 4.0};
  const V3 r1 = root + 26.0 * normalized({-0.5, 0.15, 0.87});  // right main: short, steep
  const V3 l1 = root + 45.0 * normalized({0.71, 0.1, 0.71});   // left main: long, oblique
  a.bronchi = {{
      {root, r1, 7.5, 7.0},
      {r1, r1 + 22.0 * normalized({-0.95, 0.1, -0.2}), 4.5, 4.0},  // right upper lobe
      {r1, r1 + 45.0 * normalized({-0.35, 0.2, 0.91}), 6.0, 4.5},  // intermediate → lower
      {root, l1, 6.5, 6.0},
      {l1, l1 + 20.0 * normalized({0.9, -0.2, -0.3}), 4.5, 4.0},  // left upper lobe
      {l1, l1 + 40.0 * normalized({0.3, 0.3, 0.9}), 5.0, 4.0},    // left lower lobe
  }};
  // The main bronchi start 4 mm above carina_d and overlap for a while: the single lumen they
  // form is still trachea. It divides at the first depth where the segment between the two
  // axes, in the axial slice, leaves both lumens.
  a.divide_d = a.carina_d;
  {
    const Tube& right = a.bronchi[0];
    const Tube& left = a.bronchi[3];
    auto axis_at = [](const Tube& t, double d) {
      const double s = std::clamp((d - t.a.d) / (t.b.d - t.a.d), 0.0, 1.0);
      return t.a + s * (t.b - t.a);
    };
    for (double d = a.carina_d; d < a.carina_d + 40.0; d += 0.1) {
      const V3 pr = axis_at(right, d), pl = axis_at(left, d);
      bool joined = true;
      for (int k = 0; k <= 40 && joined; ++k) {
        const V3 p = pr + (k / 40.0) * (pl - pr);
        const V3 q{p.x, p.y, d};
        joined = right.excess(q) < 0.0 || left.excess(q) < 0.0;
      }
      if (!joined) break;
      a.divide_d = d;
    }
  }

  // Ascending aorta, arch passing left of the trachea, descending beside the spine.
  const std::array<V3, 8> aorta_path{{{8.0, -40.0, 240.0},
                                      {6.0, -40.0, 150.0},
                                      {24.0, -22.0, 124.0},
                                      {30.0, 10.0, 136.0},
                                      {26.0, 24.0, 175.0},
                                      {20.0, 22.0, 300.0},
                                      {12.0, 14.0, 420.0},
                                      {10.0, 12.0, 900.0}}};
  const std::array<double, 8> aorta_r{15.0, 14.0, 13.0, 12.5, 12.0, 11.5, 10.5, 10.0};
  for (std::size_t i = 0; i < a.aorta.size(); ++i)
    a.aorta[i] = {aorta_path[i], aorta_path[i + 1], aorta_r[i], aorta_r[i + 1]};

  for (int side = 0; side < 2; ++side) {
    const double s = side == 0 ? -1.0 : 1.0;  // −1 right, +1 left
    a.clavicles[2 * side] = {{s * 14.0, -88.0, 104.0}, {s * 70.0, -86.0, 96.0}, 7.0, 7.0};
    a.clavicles[2 * side + 1] = {{s * 70.0, -86.0, 96.0}, {s * 122.0, -52.0, 88.0}, 7.0, 6.0};
    a.thyroid[side] = Ellipsoid({s * 17.0, -20.0, 45.0}, 8.0, 10.0, 22.0);
  }
  a.kidneys = {Ellipsoid({-68.0, 52.0, 440.0}, 27.0, 25.0, 55.0, -0.4),
               Ellipsoid({68.0, 48.0, 420.0}, 27.0, 25.0, 55.0, 0.4)};

  // Gallbladder: neck at the porta hepatis, fundus anterior-inferior and a little lateral.
  a.gb_axis = normalized({-0.2, -0.55, 0.8});
  const V3 up{-0.3, 0.0, -1.0};  // the liver lies above and lateral to the gallbladder
  a.gb_bed = normalized(up - dot(up, a.gb_axis) * a.gb_axis);

  for (int i = 0; i < 12; ++i) {
    Rib& r = a.ribs[std::size_t(i)];
    r.d_posterior = 95.0 + 23.0 * i;
    r.drop_mm = i == 0 ? 35.0 : (i >= 10 ? 40.0 : 80.0);
    r.theta_bone = i == 0 ? 2.7 : (i < 7 ? 2.55 : (i < 10 ? 2.35 : (i == 10 ? 1.9 : 1.5)));
    r.cartilage = i < 10;
  }
  return a;
}

// ---------------------------------------------------------------------------------------------
// Everything that depends only on the depth of a slice, computed once per slice.

/// One nested trunk layer: superellipse semi-axes (mm) around the trunk centre.
struct Layer {
  double a, b;
};

enum LayerIndex { kBody, kSkinInner, kFatInner, kCavity, kRingInner, kRingOuter, kLayerCount };

struct SliceContext {
  double d = 0.0;
  double trunk_y = 0.0;  ///< y of the trunk centre, mm
  double trunk_n = 2.0;  ///< superellipse exponent: 2 in the neck, squarer in the trunk
  std::array<Layer, kLayerCount> layers{};
  Layer ring{};  ///< centre line of the rib cage

  // Spine.
  double vb_y = 0.0, vb_r = 0.0, canal_y = 0.0, canal_r = 0.0, arch_mm = 0.0;
  double spinous_mm = 0.0, transverse_mm = 0.0;
  bool vertebral_body = true;      ///< false inside an intervertebral disc
  bool posterior_elements = true;  ///< false in the gap between two arches
  double spine_half_width = 0.0, spine_y0 = 0.0, spine_y1 = 0.0;  ///< bounding box

  // Airway and mediastinum.
  bool trachea = false;
  double trachea_x = 0.0, trachea_y = 0.0;
  std::array<int, 6> bronchi{};
  int bronchus_count = 0;
  std::array<int, 7> aorta{};
  int aorta_count = 0;
  std::array<double, 4> aorta_box{0, 0, 0, 0};  ///< x0, x1, y0, y1 around the active segments
  double esophagus_x = 0.0, esophagus_y = 0.0;
  bool ivc = false;
  double heart_q = 2.0;                   ///< depth term of the heart ellipsoid
  std::array<double, 2> thyroid_q{2, 2};  ///< depth terms of the thyroid lobes
  bool lungs = false;                     ///< below the apices
  double apex_q = 0.0;                    ///< depth term of the apical caps (0 below them)
  bool neck = true;                       ///< above the thoracic inlet: viscera, not fat

  // Abdomen.
  double stomach_q = 2.0, spleen_q = 2.0;
  std::array<double, 2> kidney_q{2, 2};
  double psoas_r = 0.0;
  bool gallbladder_near = false;  ///< the slice crosses the gallbladder or its liver bed
};

/// Every bounding test of a per-slice ellipsoid must admit this margin (q units).
constexpr double kEllipsoidMarginQ = 1.35;
/// Semi-axes of the visceral compartment of the neck, mm.
constexpr Layer kNeckCavity{38.0, 32.0};

/// 0 above the lung apices, rising like an ellipsoidal dome to 1 where the chest is full.
double dome_profile(const Anatomy& a, double d) {
  if (d <= a.apex_d) return 0.0;
  const double below_top = std::min(1.0, (d - a.apex_d) / a.apex_dome_mm);
  return std::sqrt(1.0 - sq(1.0 - below_top));
}

SliceContext make_slice(const Anatomy& a, double d) {
  SliceContext s;
  s.d = d;
  const double t = smoothstep(35.0, 105.0, d);  // neck → chest
  const double abdomen = std::max(0.0, d - 250.0);
  const double body_a = lerp(62.0, 158.0, t) - 0.03 * abdomen;
  const double body_b = lerp(56.0, 110.0, t) - 0.01 * abdomen;
  s.trunk_y = lerp(8.0, 0.0, t);
  s.trunk_n = lerp(2.0, 2.5, t);
  const double skin = 2.0;
  const double fat = std::min(lerp(7.0, 13.0, t) + 0.05 * abdomen, 24.0);
  const double muscle = lerp(14.0, 16.0, t) - 4.0 * smoothstep(280.0, 340.0, d);
  const auto inset = [&](double mm) { return Layer{body_a - mm, body_b - mm}; };
  s.layers[kBody] = inset(0.0);
  s.layers[kSkinInner] = inset(skin);
  s.layers[kFatInner] = inset(skin + fat);
  // The rib cage is a dome at the thoracic inlet: above the lung apices the trunk holds only
  // the neck viscera, and the shoulder muscles fill the space beside the upper ribs.
  const Layer full = inset(skin + fat + muscle);
  const double inlet = dome_profile(a, d);
  const Layer cavity{std::min(full.a, std::max(kNeckCavity.a, full.a * inlet)),
                     std::min(full.b, std::max(kNeckCavity.b, full.b * inlet))};
  const auto around_cavity = [&](double mm) { return Layer{cavity.a + mm, cavity.b + mm}; };
  s.layers[kCavity] = cavity;
  // Ribs lie in the inner part of the chest wall, just outside the pleura.
  s.layers[kRingInner] = around_cavity(1.5);
  s.layers[kRingOuter] = around_cavity(10.5);
  s.ring = around_cavity(6.0);

  // Spine: cervical → thoracic → lumbar sizes, thoracic kyphosis sets it back in the chest.
  const double lumbar = smoothstep(300.0, 420.0, d);
  s.vb_r = lerp(lerp(9.0, 15.0, t), 18.0, lumbar);
  s.vb_y = lerp(lerp(14.0, 45.0, t), 40.0, lumbar);
  s.canal_r = lerp(7.0, 8.0, t);
  s.arch_mm = lerp(4.0, 5.0, t);
  s.canal_y = s.vb_y + s.vb_r + 0.8 * s.canal_r;
  s.spinous_mm = lerp(14.0, 22.0, t);
  s.transverse_mm = lerp(8.0, 22.0, t);
  const double phase = std::fmod(d + 1000.0 * a.vertebra_period, a.vertebra_period);
  s.vertebral_body = phase < a.vertebra_period - a.disc_mm;
  s.posterior_elements = phase > 2.0 && phase < a.vertebra_period - 1.0;
  s.spine_half_width = s.canal_r + s.arch_mm + s.transverse_mm + 1.0;
  s.spine_y0 = s.vb_y - s.vb_r - 1.0;
  s.spine_y1 = s.canal_y + s.canal_r + s.arch_mm + s.spinous_mm + 1.0;

  s.trachea = d <= a.carina_d;
  const auto [tx, ty] = trachea_centre(a, std::min(d, a.carina_d));
  s.trachea_x = tx;
  s.trachea_y = ty;
  for (int i = 0; i < int(a.bronchi.size()); ++i) {
    const Tube& b = a.bronchi[std::size_t(i)];
    if (d >= b.d_min() - a.bronchus_wall && d <= b.d_max() + a.bronchus_wall)
      s.bronchi[std::size_t(s.bronchus_count++)] = i;
  }
  for (int i = 0; i < int(a.aorta.size()); ++i) {
    const Tube& v = a.aorta[std::size_t(i)];
    if (d < v.d_min() - 5.0 || d > v.d_max() + 5.0) continue;
    s.aorta[std::size_t(s.aorta_count++)] = i;
    // Conservative in-plane box, wide enough for the fat margin around the wall.
    const double reach = std::max(v.ra, v.rb) + 5.0;
    const std::array<double, 4> box{std::min(v.a.x, v.b.x) - reach, std::max(v.a.x, v.b.x) + reach,
                                    std::min(v.a.y, v.b.y) - reach, std::max(v.a.y, v.b.y) + reach};
    s.aorta_box = s.aorta_count == 1
                      ? box
                      : std::array<double, 4>{
                            std::min(s.aorta_box[0], box[0]), std::max(s.aorta_box[1], box[1]),
                            std::min(s.aorta_box[2], box[2]), std::max(s.aorta_box[3], box[3])};
  }
  // The esophagus follows the trachea, then swings left and forward to the stomach.
  const double to_stomach = smoothstep(220.0, 320.0, d);
  s.esophagus_x = lerp(tx + 4.0, 30.0, to_stomach);
  s.esophagus_y = lerp(ty + 19.0, 8.0, to_stomach);
  s.ivc = d >= a.ivc.d_min();

  s.heart_q = a.heart.q_depth(d);
  for (int i = 0; i < 2; ++i) s.thyroid_q[std::size_t(i)] = a.thyroid[std::size_t(i)].q_depth(d);
  s.lungs = d >= a.apex_d;
  const double apex_centre = a.apex_d + a.apex_dome_mm;
  s.apex_q = d < apex_centre ? sq((apex_centre - d) / a.apex_dome_mm) : 0.0;
  s.neck = d < a.apex_d;

  s.stomach_q = a.stomach.q_depth(d);
  s.spleen_q = a.spleen.q_depth(d);
  for (int i = 0; i < 2; ++i) s.kidney_q[std::size_t(i)] = a.kidneys[std::size_t(i)].q_depth(d);
  s.psoas_r = std::clamp(0.12 * (d - 360.0), 0.0, 16.0);

  const double gb_reach = a.gb_r_fundus + 30.0;
  const V3 fundus = a.gb_neck + a.gb_centre_distance() * a.gb_axis;
  s.gallbladder_near = d > std::min(a.gb_neck.d, fundus.d) - gb_reach &&
                       d < std::max(a.gb_neck.d, fundus.d) + gb_reach;
  return s;
}

/// Row half widths of every trunk layer (−1 where the row misses the layer).
struct RowContext {
  double y = 0.0;
  std::array<double, kLayerCount> half_width{};
};

RowContext make_row(const SliceContext& s, double y) {
  RowContext r;
  r.y = y;
  const double v = y - s.trunk_y;
  for (int l = 0; l < kLayerCount; ++l)
    r.half_width[std::size_t(l)] = superellipse_half_width(
        s.layers[std::size_t(l)].a, s.layers[std::size_t(l)].b, s.trunk_n, v);
  return r;
}

// ---------------------------------------------------------------------------------------------
// Tissue at a point. Organs are tested in priority order: bone and airway first (they cut
// through everything), then vessels, then organs, then the filling tissue of each region.

class Model {
 public:
  explicit Model(std::uint64_t seed) : a_(make_anatomy(seed)) {}
  const Anatomy& anatomy() const { return a_; }

  Tissue classify(const SliceContext& s, const RowContext& r, double x) const;
  /// A point deep inside each organ, from which the seed search starts.
  V3 preferred_seed(PhantomLabel organ) const;

 private:
  std::optional<Tissue> spine(const SliceContext& s, double x, double y) const;
  std::optional<Tissue> airway(const SliceContext& s, const RowContext& r, double x) const;
  std::optional<Tissue> chest_wall(const SliceContext& s, double x, double y) const;
  /// `aorta_mm`: distance outside the aortic wall (the aorta itself is handled by the caller).
  Tissue thorax(const SliceContext& s, const RowContext& r, double x, double aorta_mm) const;
  Tissue abdomen(const SliceContext& s, const RowContext& r, double x) const;
  bool lung_region(const SliceContext& s, const RowContext& r, double x) const;
  double aorta_excess(const SliceContext& s, V3 p) const;
  double diaphragm_d(double x, double y) const;
  bool paraspinal(const SliceContext& s, double x, double y) const;
  /// Gallbladder: +1 inside, 0 in the liver bed, −1 on its free side, nullopt elsewhere.
  std::optional<int> gallbladder(V3 p) const;
  bool liver(const SliceContext& s, double x, double y) const;

  Anatomy a_;
};

double Model::diaphragm_d(double x, double y) const {
  // Paraboloid domes, right higher than left, and the flatter central tendon under the heart;
  // the lungs end at the highest (smallest d) of them. The recesses reach far lower behind
  // (posterior costophrenic recess) than in front.
  const auto dome = [&](const V3& c) {
    const double dy = y - c.y;
    return c.d + 55.0 * sq((x - c.x) / 85.0) + (dy < 0.0 ? 25.0 : 55.0) * sq(dy / 80.0);
  };
  const double tendon = a_.central_tendon.d + 60.0 * (sq((x - a_.central_tendon.x) / 60.0) +
                                                      sq((y - a_.central_tendon.y) / 50.0));
  return std::min({dome(a_.dome_right), dome(a_.dome_left), tendon});
}

bool Model::paraspinal(const SliceContext& s, double x, double y) const {
  // The erector spinae fill the gutter behind the transverse processes; the lungs curve
  // around them.
  return sq(x / 46.0) + sq((y - s.canal_y - 22.0) / 30.0) < 1.0 ||
         (std::abs(x) < 30.0 && y > s.canal_y);
}

double Model::aorta_excess(const SliceContext& s, V3 p) const {
  double e = std::numeric_limits<double>::infinity();
  if (p.x < s.aorta_box[0] || p.x > s.aorta_box[1] || p.y < s.aorta_box[2] || p.y > s.aorta_box[3])
    return e;
  for (int i = 0; i < s.aorta_count; ++i)
    e = std::min(e, a_.aorta[std::size_t(s.aorta[std::size_t(i)])].excess(p));
  return e;
}

std::optional<Tissue> Model::spine(const SliceContext& s, double x, double y) const {
  const double ax = std::abs(x);
  if (ax > s.spine_half_width || y < s.spine_y0 || y > s.spine_y1) return std::nullopt;
  const double body_r2 = sq(x) + sq(y - s.vb_y);
  if (body_r2 < sq(s.vb_r)) {
    if (!s.vertebral_body) return body(hu::disc);
    return body(body_r2 > sq(s.vb_r - 2.0) ? hu::cortical : hu::cancellous);
  }
  const double dyc = y - s.canal_y;
  const double canal_r2 = sq(x) + sq(dyc);
  if (canal_r2 < sq(s.canal_r)) return body(hu::csf);
  if (!s.posterior_elements) return std::nullopt;
  const double outer = s.canal_r + s.arch_mm;
  const bool arch = canal_r2 < sq(outer) && dyc > -0.3 * s.canal_r;
  const bool pedicle = ax > 0.5 * s.canal_r && ax < outer && y > s.vb_y && y < s.canal_y;
  const bool spinous = ax < 3.5 && dyc > 0.0 && dyc < outer + s.spinous_mm;
  const bool transverse = std::abs(dyc + 1.0) < 4.5 && ax < outer + s.transverse_mm;
  if (arch || pedicle || spinous || transverse) return body(hu::compact);
  return std::nullopt;
}

std::optional<Tissue> Model::airway(const SliceContext& s, const RowContext& r, double x) const {
  const double y = r.y;
  if (s.trachea) {
    const double rho2 = sq(x - s.trachea_x) + sq(y - s.trachea_y);
    if (rho2 < sq(a_.trachea_lumen_r)) return Tissue{hu::air, PhantomLabel::trachea};
    if (rho2 < sq(a_.trachea_lumen_r + a_.trachea_wall)) return body(hu::airway_wall);
  }
  if (s.bronchus_count == 0) return std::nullopt;
  const V3 p{x, y, s.d};
  double e = std::numeric_limits<double>::infinity();
  for (int i = 0; i < s.bronchus_count; ++i)
    e = std::min(e, a_.bronchi[std::size_t(s.bronchi[std::size_t(i)])].excess(p));
  // Bronchi belong to the lungs (label 4); their shared lumen above the division is trachea.
  if (e < 0.0) return Tissue{hu::air, s.d <= a_.divide_d ? PhantomLabel::trachea : PhantomLabel::lungs};
  if (e < a_.bronchus_wall)
    return Tissue{hu::airway_wall, lung_region(s, r, x) ? PhantomLabel::lungs : PhantomLabel::body};
  return std::nullopt;
}

std::optional<Tissue> Model::chest_wall(const SliceContext& s, double x, double y) const {
  if (s.d < 80.0) return std::nullopt;
  const double u = std::abs(x) / s.ring.a;
  const double v = (y - s.trunk_y) / s.ring.b;
  const double theta = std::atan2(u, v);  // 0 posterior, π/2 lateral, π anterior
  // Offset across the chest wall from the rib centre line, mm (positive outward).
  const double rho =
      std::pow(std::pow(u, s.trunk_n) + std::pow(std::abs(v), s.trunk_n), 1.0 / s.trunk_n);
  const double offset = (rho - 1.0) * std::hypot(x, y - s.trunk_y) / rho;

  if (s.d > 105.0 && s.d < 290.0 && theta > 2.6) {
    const double half_width = s.d < 150.0 ? 26.0 : (s.d < 265.0 ? 16.0 : 8.0);  // manubrium…
    if (std::abs(x) < half_width && std::abs(offset) < 5.5) return body(hu::compact);
  }
  constexpr double theta0 = 0.28;  // the rib leaves the transverse process here
  if (theta < theta0) return std::nullopt;
  const double along = std::pow((theta - theta0) / (kPi - theta0), 1.1);
  for (const Rib& rib : a_.ribs) {
    const double dd = s.d - (rib.d_posterior + rib.drop_mm * along);
    if (std::abs(dd) > 6.0) continue;
    const double level = sq(offset / 4.5) + sq(dd / 6.0);
    if (level > 1.0) continue;
    if (theta < rib.theta_bone)
      return body(sq(offset / 3.0) + sq(dd / 4.5) > 1.0 ? hu::cortical : hu::cancellous);
    if (rib.cartilage && theta < kPi - 0.1) return body(hu::cartilage);
  }
  return std::nullopt;
}

bool Model::lung_region(const SliceContext& s, const RowContext& r, double x) const {
  const double y = r.y;
  if (!s.lungs || std::abs(x) >= r.half_width[kCavity]) return false;
  if (s.d >= diaphragm_d(x, y)) return false;
  if (s.apex_q > 0.0) {
    // Each apex is a cap of an ellipsoid centred over the lung's upper lobe.
    // Wider than the chest once fully open, so that the caps end without a step.
    const double cx = x < 0.0 ? -48.0 : 48.0;
    if (sq((x - cx) / 85.0) + sq((y - 5.0) / 100.0) + s.apex_q > 1.0) return false;
  }
  // The mediastinum is widest around the trachea and great vessels, narrow behind the
  // sternum where the lungs almost meet.
  const double mediastinum =
      y < -60.0 ? 10.0
                : (y < -30.0 ? lerp(10.0, 22.0, (y + 60.0) / 30.0)
                             : (y < 20.0 ? lerp(22.0, 26.0, (y + 30.0) / 50.0) : 22.0));
  if (std::abs(x - 3.0) < mediastinum) return false;
  if (sq(x) + sq(y - s.vb_y) < sq(s.vb_r + 5.0)) return false;
  if (paraspinal(s, x, y)) return false;
  return true;
}

Tissue Model::thorax(const SliceContext& s, const RowContext& r, double x, double aorta_mm) const {
  const double y = r.y;
  if (s.heart_q < kEllipsoidMarginQ) {
    const double q = a_.heart.q_plane(x, y) + s.heart_q;
    if (q < 1.0) return body(hu::blood);
    if (q < 1.25) return body(hu::fat);  // epicardial fat
  }
  if (s.neck) {
    for (int i = 0; i < 2; ++i)
      if (s.thyroid_q[std::size_t(i)] < 1.0 &&
          a_.thyroid[std::size_t(i)].q_plane(x, y) + s.thyroid_q[std::size_t(i)] < 1.0)
        return body(hu::thyroid);
    return body(hu::soft_tissue);
  }
  if (aorta_mm < 3.0) return body(hu::fat);  // the aorta runs in mediastinal fat
  if (lung_region(s, r, x)) return Tissue{hu::lung, PhantomLabel::lungs};
  return body(hu::fat);  // mediastinal fat
}

std::optional<int> Model::gallbladder(V3 p) const {
  const double length = a_.gb_centre_distance();
  const double along = dot(p - a_.gb_neck, a_.gb_axis);
  if (along < -40.0 || along > length + 50.0) return std::nullopt;
  const double s01 = clamp01(along / length);
  const V3 off = p - (a_.gb_neck + (s01 * length) * a_.gb_axis);
  const double dist = norm(off);
  const double radius = a_.gb_radius(s01);
  if (dist < radius) return 1;
  // The liver wraps the gallbladder from above (its bed, the fossa); below, it is free and
  // touches fat, as in a real fossa that opens onto the visceral surface.
  const double side = dot(off, a_.gb_bed) / dist;
  if (side > -0.2) return dist < radius + 10.0 ? std::optional<int>(0) : std::nullopt;
  return dist < radius + 12.0 ? std::optional<int>(-1) : std::nullopt;
}

bool Model::liver(const SliceContext& s, double x, double y) const {
  // Medial edge: the left lobe reaches across the midline anteriorly and recedes lower down.
  const double x_anterior = 70.0 - 1.3 * std::max(0.0, s.d - 290.0);
  const double x_limit = lerp(-22.0, x_anterior, smoothstep(50.0, -90.0, y));
  // Visceral surface: lowest at the right lateral edge and posteriorly.
  const double d_inferior = 385.0 - 0.3 * (x + 60.0) + 0.15 * y;
  if (x > x_limit || s.d > d_inferior) return false;
  if (sq(x) + sq(y - s.vb_y) < sq(s.vb_r + 6.0) || paraspinal(s, x, y)) return false;
  return true;
}

Tissue Model::abdomen(const SliceContext& s, const RowContext& r, double x) const {
  const double y = r.y;
  const V3 p{x, y, s.d};
  std::optional<int> gb;
  if (s.gallbladder_near) {
    gb = gallbladder(p);
    if (gb == 1) return Tissue{hu::bile, PhantomLabel::gallbladder};
  }
  // Solid organs come with a thin fat capsule so that their outlines stay visible.
  const auto organ = [&](const Ellipsoid& e, double depth_q, float value) -> std::optional<Tissue> {
    if (depth_q >= kEllipsoidMarginQ) return std::nullopt;
    const double q = e.q_plane(x, y) + depth_q;
    if (q < 1.0) return body(value);
    if (q < 1.2) return body(hu::fat);
    return std::nullopt;
  };
  for (int i = 0; i < 2; ++i)
    if (auto t = organ(a_.kidneys[std::size_t(i)], s.kidney_q[std::size_t(i)], hu::kidney))
      return *t;
  if (s.stomach_q < kEllipsoidMarginQ) {
    const double q = a_.stomach.q_plane(x, y) + s.stomach_q;
    // Supine: gas rises to the anterior part of the lumen.
    const double gas_level = a_.stomach.c.y - 0.35 * a_.stomach.ry;
    if (q < 0.85) return body(y < gas_level ? hu::air : hu::gastric_fluid);
    if (q < 1.0) return body(hu::soft_tissue);  // gastric wall
    if (q < 1.15) return body(hu::fat);
  }
  if (auto t = organ(a_.spleen, s.spleen_q, hu::spleen)) return *t;
  if (gb == 0) return Tissue{hu::liver, PhantomLabel::liver};
  if (gb != -1 && liver(s, x, y)) return Tissue{hu::liver, PhantomLabel::liver};
  if (s.psoas_r > 0.0) {
    const double px = std::abs(x) - (s.vb_r + 0.6 * s.psoas_r + 4.0);
    if (sq(px / s.psoas_r) + sq((y - s.vb_y - 2.0) / (1.2 * s.psoas_r)) < 1.0)
      return body(hu::muscle);
  }
  // Bowel loops in the left and lower abdomen. They fade out toward the gallbladder, whose
  // free wall usually faces fat; raising the threshold smoothly avoids a seam.
  const double sparse = 1.2 * smoothstep(15.0, -10.0, x) * (1.0 - smoothstep(390.0, 420.0, s.d));
  const double loops =
      std::sin(0.11 * x + 1.3 * std::sin(0.05 * s.d)) * std::sin(0.1 * y + 0.04 * x) +
      0.45 * std::sin(0.09 * s.d + 0.05 * x - 0.04 * y);
  return body(loops > 0.35 + sparse ? hu::bowel : hu::fat);
}

Tissue Model::classify(const SliceContext& s, const RowContext& r, double x) const {
  const double ax = std::abs(x);
  const double y = r.y;
  if (ax >= r.half_width[kBody]) return kAir;
  if (ax >= r.half_width[kSkinInner]) return body(hu::skin);
  if (ax >= r.half_width[kFatInner]) return body(hu::fat);
  if (auto t = spine(s, x, y)) return *t;
  if (auto t = airway(s, r, x)) return *t;
  const V3 p{x, y, s.d};
  if (s.d > 80.0 && s.d < 115.0) {
    for (const Tube& c : a_.clavicles)
      if (c.excess(p) < 0.0) return body(hu::compact);
  }
  const bool in_cavity = ax < r.half_width[kCavity] && !paraspinal(s, x, y);
  if (!in_cavity) {
    if (ax < r.half_width[kRingOuter] && ax >= std::max(0.0, r.half_width[kRingInner]) - 1e-9)
      if (auto t = chest_wall(s, x, y)) return *t;
    return body(hu::muscle);
  }
  // Tubular viscera running through the whole trunk.
  if (sq((x - s.esophagus_x) / 9.0) + sq((y - s.esophagus_y) / 6.5) < 1.0)
    return body(hu::soft_tissue);
  const double aorta =
      s.aorta_count > 0 ? aorta_excess(s, p) : std::numeric_limits<double>::infinity();
  if (aorta < 0.0) return body(hu::blood);
  if (s.ivc && std::abs(x - a_.ivc.a.x) < 15.0 && std::abs(y - a_.ivc.a.y) < 15.0 &&
      a_.ivc.excess(p) < 0.0)
    return body(hu::blood);

  const double diaphragm = diaphragm_d(x, y);
  if (s.d < diaphragm) return thorax(s, r, x, aorta);
  if (s.d < diaphragm + a_.diaphragm_mm) return body(hu::muscle);
  return abdomen(s, r, x);
}

V3 Model::preferred_seed(PhantomLabel organ) const {
  switch (organ) {
    case PhantomLabel::gallbladder:
      return a_.gb_neck + (0.6 * a_.gb_centre_distance()) * a_.gb_axis;
    case PhantomLabel::trachea: {
      const double d = 0.5 * a_.carina_d;
      const auto [x, y] = trachea_centre(a_, d);
      return {x, y, d};
    }
    case PhantomLabel::liver:
      return {-85.0, 5.0, 335.0};
    case PhantomLabel::lungs:
      return {-85.0, 10.0, 200.0};
    default:
      return {0.0, 0.0, 0.0};
  }
}

// ---------------------------------------------------------------------------------------------
// Volume-level passes.

void validate(const PhantomOptions& o) {
  const auto bad = [](const std::string& what) {
    throw UsageError("invalid phantom option: " + what,
                     "use size_vox ≥ 16, positive slice_mm and fov_mm, extent_mm ≥ 100 and ≥ "
                     "two slices, blur_mm ≥ 0, noise_hu ≥ 0");
  };
  if (o.size_vox < 16 || o.size_vox > 4096) bad("size_vox = " + std::to_string(o.size_vox));
  if (!(o.slice_mm > 0.0) || !std::isfinite(o.slice_mm))
    bad("slice_mm = " + std::to_string(o.slice_mm));
  if (!(o.fov_mm > 0.0) || !std::isfinite(o.fov_mm)) bad("fov_mm = " + std::to_string(o.fov_mm));
  if (!(o.extent_mm >= 100.0) || !std::isfinite(o.extent_mm) || o.extent_mm < 2.0 * o.slice_mm)
    bad("extent_mm = " + std::to_string(o.extent_mm));
  if (!(o.blur_mm >= 0.0) || !std::isfinite(o.blur_mm))
    bad("blur_mm = " + std::to_string(o.blur_mm));
  if (!(o.noise_hu >= 0.0) || !std::isfinite(o.noise_hu))
    bad("noise_hu = " + std::to_string(o.noise_hu));
}

ImageGrid make_grid(const PhantomOptions& o) {
  ImageGrid g;
  const std::int64_t slices = std::max<std::int64_t>(2, std::llround(o.extent_mm / o.slice_mm));
  g.size_vox = {o.size_vox, o.size_vox, slices};
  const double pixel_mm = o.fov_mm / o.size_vox;
  g.spacing_mm = {pixel_mm, pixel_mm, o.slice_mm};
  const double first_mm = -0.5 * o.fov_mm + 0.5 * pixel_mm;
  g.origin_lps_mm = {first_mm, first_mm, -double(slices - 1) * o.slice_mm};
  return g;
}

/// Canonical depth per mm of z: 1 for volumes of at least the canonical length, larger for
/// shorter ones, whose anatomy is compressed so that it all still fits.
double depth_per_z_mm(const ImageGrid& g) {
  const double length_mm = double(g.size_vox[2]) * g.spacing_mm.z();
  return std::max(1.0, kCanonicalLength_mm / length_mm);
}

double slice_depth(const ImageGrid& g, std::int64_t k) {
  return double(g.size_vox[2] - 1 - k) * g.spacing_mm.z() * depth_per_z_mm(g);
}

/// Normalised Gaussian taps for sigma in voxels; a single tap when blurring would not change
/// anything measurable.
std::vector<float> gaussian_taps(double sigma_vox) {
  if (sigma_vox < 0.2) return {1.0f};
  const int radius = int(std::ceil(3.0 * sigma_vox));
  std::vector<double> w(std::size_t(2 * radius + 1));
  double sum = 0.0;
  for (int t = -radius; t <= radius; ++t)
    sum += w[std::size_t(t + radius)] = std::exp(-0.5 * sq(t / sigma_vox));
  std::vector<float> taps(w.size());
  for (std::size_t i = 0; i < w.size(); ++i) taps[i] = float(w[i] / sum);
  return taps;
}

/// Convolves every row of an nx × ny slice along x, in place, replicating the edges.
void blur_rows(float* slice, std::int64_t nx, std::int64_t ny, const std::vector<float>& taps,
               std::vector<float>& scratch) {
  const std::int64_t radius = std::int64_t(taps.size() / 2);
  scratch.resize(std::size_t(nx + 2 * radius));
  float* padded = scratch.data();
  for (std::int64_t j = 0; j < ny; ++j) {
    float* row = slice + j * nx;
    for (std::int64_t t = 0; t < nx + 2 * radius; ++t)
      padded[t] = row[std::clamp<std::int64_t>(t - radius, 0, nx - 1)];
    std::fill(row, row + nx, 0.0f);
    // Taps outside, voxels inside: the inner loop is contiguous and vectorises.
    for (std::size_t w = 0; w < taps.size(); ++w) {
      const float tap = taps[w];
      const float* in = padded + w;
      for (std::int64_t i = 0; i < nx; ++i) row[i] += tap * in[i];
    }
  }
}

/// Convolves along an axis whose samples are `stride` floats apart, for `width` contiguous
/// lines at once (sample t of line c is data[t * stride + c]), in place, replicating the edges.
void blur_across(float* data, std::int64_t length, std::int64_t stride, std::int64_t width,
                 const std::vector<float>& taps, std::vector<float>& scratch) {
  const std::int64_t radius = std::int64_t(taps.size() / 2);
  scratch.resize(std::size_t((length + 2 * radius) * width));
  for (std::int64_t t = 0; t < length + 2 * radius; ++t) {
    const float* src = data + std::clamp<std::int64_t>(t - radius, 0, length - 1) * stride;
    std::copy(src, src + width, scratch.data() + t * width);
  }
  for (std::int64_t t = 0; t < length; ++t) {
    float* out = data + t * stride;
    std::fill(out, out + width, 0.0f);
    for (std::size_t w = 0; w < taps.size(); ++w) {
      const float tap = taps[w];
      const float* in = scratch.data() + (t + std::int64_t(w)) * width;
      for (std::int64_t c = 0; c < width; ++c) out[c] += tap * in[c];
    }
  }
}

/// Reports progress of phase `phase` (of `phases`) from TBB workers, at most once per item.
class PhaseProgress {
 public:
  PhaseProgress(Progress& progress, int phase, int phases, std::int64_t items)
      : progress_(progress), phase_(phase), phases_(phases), items_(items) {}
  void item_done() {
    progress_.check_cancelled();
    const std::int64_t done = ++done_;
    progress_.report((phase_ + double(done) / double(items_)) / phases_, kTask);
  }

 private:
  Progress& progress_;
  int phase_, phases_;
  std::int64_t items_;
  std::atomic<std::int64_t> done_{0};
};

void synthesize_slices(const Model& model, Volume& ct, LabelMap& truth, Progress& progress) {
  const ImageGrid& g = ct.grid;
  const std::int64_t nx = g.size_vox[0], ny = g.size_vox[1], nz = g.size_vox[2];
  PhaseProgress phase(progress, 0, 4, nz);
  tbb::parallel_for(
      tbb::blocked_range<std::int64_t>(0, nz), [&](const tbb::blocked_range<std::int64_t>& range) {
        for (std::int64_t k = range.begin(); k < range.end(); ++k) {
          const SliceContext s = make_slice(model.anatomy(), slice_depth(g, k));
          for (std::int64_t j = 0; j < ny; ++j) {
            const RowContext r = make_row(s, g.origin_lps_mm.y() + double(j) * g.spacing_mm.y());
            float* hu_row = ct.hu.data() + g.offset(0, j, k);
            std::uint8_t* label_row = truth.labels.data() + g.offset(0, j, k);
            // Air outside the body needs no classification: only the columns the body can reach
            // (plus one for rounding) go through classify().
            std::fill(hu_row, hu_row + nx, hu::air);
            std::fill(label_row, label_row + nx, std::uint8_t(PhantomLabel::background));
            const double half_width = r.half_width[kBody];
            if (half_width < 0.0) continue;
            const double x0 = g.origin_lps_mm.x(), dx = g.spacing_mm.x();
            const std::int64_t i0 =
                std::max<std::int64_t>(0, std::int64_t(std::floor((-half_width - x0) / dx)) - 1);
            const std::int64_t i1 =
                std::min<std::int64_t>(nx, std::int64_t(std::ceil((half_width - x0) / dx)) + 2);
            for (std::int64_t i = i0; i < i1; ++i) {
              const Tissue t = model.classify(s, r, x0 + double(i) * dx);
              hu_row[i] = t.hu;
              label_row[i] = std::uint8_t(t.label);
            }
          }
          phase.item_done();
        }
      });
}

void blur(Volume& ct, double sigma_mm, Progress& progress) {
  const ImageGrid& g = ct.grid;
  const std::int64_t nx = g.size_vox[0], ny = g.size_vox[1], nz = g.size_vox[2];
  const auto taps_x = gaussian_taps(sigma_mm / g.spacing_mm.x());
  const auto taps_y = gaussian_taps(sigma_mm / g.spacing_mm.y());
  const auto taps_z = gaussian_taps(sigma_mm / g.spacing_mm.z());
  float* data = ct.hu.data();
  {
    PhaseProgress phase(progress, 1, 4, nz);
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, nz),
                      [&](const tbb::blocked_range<std::int64_t>& range) {
                        std::vector<float> scratch;
                        for (std::int64_t k = range.begin(); k < range.end(); ++k) {
                          float* slice = data + k * nx * ny;
                          if (taps_x.size() > 1) blur_rows(slice, nx, ny, taps_x, scratch);
                          if (taps_y.size() > 1) blur_across(slice, ny, nx, nx, taps_y, scratch);
                          phase.item_done();
                        }
                      });
  }
  PhaseProgress phase(progress, 2, 4, ny);
  if (taps_z.size() == 1) {
    for (std::int64_t j = 0; j < ny; ++j) phase.item_done();
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, ny),
                    [&](const tbb::blocked_range<std::int64_t>& range) {
                      std::vector<float> scratch;
                      for (std::int64_t j = range.begin(); j < range.end(); ++j) {
                        blur_across(data + j * nx, nz, nx * ny, nx, taps_z, scratch);
                        phase.item_done();
                      }
                    });
}

void add_noise_and_quantize(Volume& ct, double sigma_hu, std::uint64_t seed, Progress& progress) {
  const ImageGrid& g = ct.grid;
  const std::int64_t per_slice = g.slice_voxel_count(), nz = g.size_vox[2];
  PhaseProgress phase(progress, 3, 4, nz);
  const Ziggurat normal;
  tbb::parallel_for(
      tbb::blocked_range<std::int64_t>(0, nz), [&](const tbb::blocked_range<std::int64_t>& range) {
        for (std::int64_t k = range.begin(); k < range.end(); ++k) {
          SplitMix64 rng(mix64(seed * 0x9E3779B97F4A7C15ULL + std::uint64_t(k)) ^ 0xC7A5EEDULL);
          float* v = ct.hu.data() + k * per_slice;
          for (std::int64_t n = 0; n < per_slice; ++n) {
            const double noisy = sigma_hu > 0.0 ? v[n] + sigma_hu * normal.draw(rng) : double(v[n]);
            // Integral HU, so that writing int16 DICOM is lossless.
            v[n] = std::clamp(float(std::nearbyint(noisy)), hu::min, hu::max);
          }
          phase.item_done();
        }
      });
}

/// The seed of `organ`: the voxel centre nearest to `preferred_lps_mm` among voxels of the
/// organ whose six neighbours also belong to it, so the seed lies strictly inside even where
/// the organ is thin on a coarse grid; failing that, any voxel of the organ. Only voxels within
/// `reach_mm` of the preferred point (per axis) are searched. nullopt when none qualifies.
std::optional<Eigen::Vector3d> find_seed(const LabelMap& truth, PhantomLabel organ,
                                         const Eigen::Vector3d& preferred_lps_mm, double reach_mm) {
  const ImageGrid& g = truth.grid;
  const std::uint8_t value = std::uint8_t(organ);
  const Eigen::Vector3d target = g.lps_mm_to_index(preferred_lps_mm);
  std::array<std::int64_t, 3> lo{}, hi{};
  for (int a = 0; a < 3; ++a) {
    const double reach_vox = reach_mm / g.spacing_mm[a];
    lo[std::size_t(a)] = std::clamp<std::int64_t>(std::int64_t(std::floor(target[a] - reach_vox)),
                                                  0, g.size_vox[std::size_t(a)]);
    hi[std::size_t(a)] = std::clamp<std::int64_t>(
        std::int64_t(std::ceil(target[a] + reach_vox)) + 1, 0, g.size_vox[std::size_t(a)]);
  }
  const auto same = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    return g.contains(i, j, k) && truth.at(i, j, k) == value;
  };
  struct Best {
    double d2 = std::numeric_limits<double>::infinity();
    std::array<std::int64_t, 3> ijk{-1, -1, -1};
  };
  // Scanned in a fixed order, so ties resolve the same way every time.
  std::array<Best, 2> best{};  // [0] interior voxels, [1] any voxel
  for (std::int64_t k = lo[2]; k < hi[2]; ++k)
    for (std::int64_t j = lo[1]; j < hi[1]; ++j)
      for (std::int64_t i = lo[0]; i < hi[0]; ++i) {
        if (truth.at(i, j, k) != value) continue;
        const Eigen::Vector3d delta_mm =
            g.spacing_mm.cwiseProduct(Eigen::Vector3d(double(i), double(j), double(k)) - target);
        const double d2 = delta_mm.squaredNorm();
        const bool interior = same(i + 1, j, k) && same(i - 1, j, k) && same(i, j + 1, k) &&
                              same(i, j - 1, k) && same(i, j, k + 1) && same(i, j, k - 1);
        for (std::size_t c = interior ? 0 : 1; c < 2; ++c)
          if (d2 < best[c].d2) best[c] = {d2, {i, j, k}};
      }
  for (const Best& b : best)
    if (b.ijk[0] >= 0)
      return g.index_to_lps_mm(
          Eigen::Vector3d(double(b.ijk[0]), double(b.ijk[1]), double(b.ijk[2])));
  return std::nullopt;
}

}  // namespace

std::string phantom_label_name(PhantomLabel label) {
  switch (label) {
    case PhantomLabel::background: return "background";
    case PhantomLabel::gallbladder: return "gallbladder";
    case PhantomLabel::trachea: return "trachea";
    case PhantomLabel::liver: return "liver";
    case PhantomLabel::lungs: return "lungs";
    case PhantomLabel::body: return "body";
  }
  return "label" + std::to_string(int(label));
}

Phantom synthesize_phantom(const PhantomOptions& options, Progress& progress) {
  validate(options);
  progress.check_cancelled();
  Phantom out;
  const ImageGrid grid = make_grid(options);
  out.ct.grid = grid;
  out.truth.grid = grid;
  // Not zeroed (VoxelBuffer): synthesize_slices writes every voxel, on the worker threads.
  out.ct.hu.resize(std::size_t(grid.voxel_count()));
  out.truth.labels.resize(std::size_t(grid.voxel_count()));

  const Model model(options.seed);
  progress.report(0.0, kTask);
  synthesize_slices(model, out.ct, out.truth, progress);
  blur(out.ct, options.blur_mm, progress);
  add_noise_and_quantize(out.ct, options.noise_hu, options.seed, progress);

  const double top_z = grid.origin_lps_mm.z() + double(grid.size_vox[2] - 1) * grid.spacing_mm.z();
  const double z_per_depth = 1.0 / depth_per_z_mm(grid);
  for (PhantomLabel organ : {PhantomLabel::gallbladder, PhantomLabel::trachea, PhantomLabel::liver, PhantomLabel::lungs}) {
    const V3 p = model.preferred_seed(organ);
    const Eigen::Vector3d preferred(p.x, p.y, top_z - p.d * z_per_depth);
    // The preferred points lie deep inside their organs, so a small search box nearly always
    // suffices; the whole volume is the fallback for odd grids.
    auto seed = find_seed(out.truth, organ, preferred, 30.0);
    if (!seed) seed = find_seed(out.truth, organ, preferred, 1e7);
    if (seed) out.seeds_lps_mm[phantom_label_name(organ)] = *seed;
  }
  progress.report(1.0, kTask);
  return out;
}

}  // namespace organsmith
