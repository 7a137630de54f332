// Over 400 lines: the one place that orders the steps of the three mesh models (wall and body,
// tube, solid), checks their inputs and applies the remedies when a gate fails.
// Orchestration of the meshing stage: per organ, prepare the smoothed field, sample and remesh
// the surfaces, build the wall bodies and tetrahedra, and measure everything. No CGAL here.

#include "meshing/mesh.h"
#include "core/format.h"

#include "core/errors.h"
#include "meshing/detail.h"
#include "meshing/tet_improve.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <exception>
#include <array>
#include <limits>
#include <mutex>
#include <sstream>

namespace organsmith {

using namespace meshing_detail;

MeshQualityError::MeshQualityError(std::string message, std::string hint)
    : Error(ExitCode::mesh_quality, std::move(message), {}, std::move(hint)) {}

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string fmt(double v, int digits = 3) { return format_g(v, digits); }

/// Per-step wall times of one organ (branches of an organ record from their own threads).
class Timeline {
 public:
  explicit Timeline(std::chrono::steady_clock::time_point t0) : t0_(t0) {}
  double now() const { return seconds_since(t0_); }
  void add(std::string step, double start_s, double end_s) {
    std::lock_guard<std::mutex> lock(m_);
    steps_.push_back({std::move(step), start_s, end_s});
  }
  std::vector<MeshStepTime> take() { return std::move(steps_); }

  /// Records the step from construction to destruction.
  struct Scope {
    Timeline& tl;
    std::string step;
    double start = tl.now();
    ~Scope() { tl.add(std::move(step), start, tl.now()); }
  };

 private:
  std::chrono::steady_clock::time_point t0_;
  std::mutex m_;
  std::vector<MeshStepTime> steps_;
};

/// An organ's mask cropped (with a margin) out of the label map, in the grid frame.
struct Prepared {
  std::array<std::int64_t, 3> b0{}, b1{};  ///< bounding box of the label (voxel indices)
  std::array<std::int64_t, 3> lo{}, n{};   ///< crop origin (may lie outside the image) and size
  std::array<bool, 6> cut{};               ///< surface cut flat on side (axis, low/high)
  Field3 field;                            ///< smoothed mask (1 inside) on the crop
  Box clip{Eigen::Vector3d::Constant(-kInf), Eigen::Vector3d::Constant(kInf)};
  Box extended;                            ///< clip box widened on cut sides; the implicit domain ends here
  Box domain;                              ///< Mesh_3 bounding box
  LabelMap kept;                           ///< the voxels meshed (1), on a crop of the input grid
  double label_volume_mm3 = 0, dropped_volume_mm3 = 0;
  float iso = 0.5f;
  Field3 fine;                             ///< `field` resampled finely (volume calibration, distances)
};

/// 6-connected components of `on` cells in an n-grid; returns per-cell component id (−1 off).
std::vector<std::int32_t> components(const std::vector<std::uint8_t>& on, const std::array<std::int64_t, 3>& n,
                                     std::vector<std::int64_t>& sizes, bool value) {
  std::vector<std::int32_t> id(on.size(), -1);
  std::vector<std::int64_t> stack;
  for (std::int64_t s = 0; s < std::int64_t(on.size()); ++s) {
    if (bool(on[s]) != value || id[s] >= 0) continue;
    const std::int32_t c = std::int32_t(sizes.size());
    sizes.push_back(0);
    stack.push_back(s);
    id[s] = c;
    while (!stack.empty()) {
      const std::int64_t x = stack.back();
      stack.pop_back();
      ++sizes[c];
      const std::int64_t i = x % n[0], j = (x / n[0]) % n[1], k = x / (n[0] * n[1]);
      const std::int64_t nb[6][3] = {{i - 1, j, k}, {i + 1, j, k}, {i, j - 1, k}, {i, j + 1, k}, {i, j, k - 1}, {i, j, k + 1}};
      for (const auto& q : nb) {
        if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= n[0] || q[1] >= n[1] || q[2] >= n[2]) continue;
        const std::int64_t y = q[0] + n[0] * (q[1] + n[1] * q[2]);
        if (bool(on[y]) == value && id[y] < 0) {
          id[y] = c;
          stack.push_back(y);
        }
      }
    }
  }
  return id;
}

/// Drops the voxels one voxel thin: those with neither neighbour inside along some axis (a plate
/// one slice thick sticking out past both neighbouring slices' sections, a spur one pixel wide).
/// No smooth surface at the grid's resolution carries them: a surface round a part one voxel
/// thick folds within half a voxel. Returns the thin voxels (indices into the mask), dropped
/// unless they are half the mask or more (then the mask is left as it is).
std::vector<std::int64_t> drop_one_voxel_thin(std::vector<std::uint8_t>& mask, const std::array<std::int64_t, 3>& n) {
  const std::int64_t st[3] = {1, n[0], n[0] * n[1]};
  std::vector<std::int64_t> thin;
  std::int64_t inside = 0;
  for (std::int64_t k = 0, x = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i, ++x) {
        if (!mask[std::size_t(x)]) continue;
        ++inside;
        const std::int64_t c[3] = {i, j, k};
        for (int a = 0; a < 3; ++a) {
          if (n[a] < 3) continue;
          const bool lo = c[a] > 0 && mask[std::size_t(x - st[a])], hi = c[a] + 1 < n[a] && mask[std::size_t(x + st[a])];
          if (!lo && !hi) {
            thin.push_back(x);
            break;
          }
        }
      }
  // Parts, not organs: a label that is mostly one voxel thin (an organ found on one slice) has
  // no smooth surface at this grid; the caller refuses it.
  if (2 * std::int64_t(thin.size()) >= inside) return thin;
  for (const std::int64_t x : thin) mask[std::size_t(x)] = 0;
  return thin;
}

Prepared prepare(const LabelMap& lm, const MeshOrganSpec& spec, const MeshOptions& o, std::vector<std::string>& warnings) {
  Prepared p;
  const auto& g = lm.grid;
  const auto N = g.size_vox;
  const Eigen::Vector3d s = g.spacing_mm;
  for (int a = 0; a < 3; ++a) p.b0[a] = N[a], p.b1[a] = -1;
  std::int64_t count = 0;
  for (std::int64_t k = 0; k < N[2]; ++k)
    for (std::int64_t j = 0; j < N[1]; ++j)
      for (std::int64_t i = 0; i < N[0]; ++i)
        if (lm.labels[g.offset(i, j, k)] == spec.label) {
          ++count;
          p.b0 = {std::min(p.b0[0], i), std::min(p.b0[1], j), std::min(p.b0[2], k)};
          p.b1 = {std::max(p.b1[0], i), std::max(p.b1[1], j), std::max(p.b1[2], k)};
        }
  if (count == 0) return p;  // caller reports absence
  if (p.b0 == std::array<std::int64_t, 3>{0, 0, 0} && p.b1 == std::array<std::int64_t, 3>{N[0] - 1, N[1] - 1, N[2] - 1})
    throw MeshInputError(spec.name + " (label " + std::to_string(int(spec.label)) +
                             ") touches all six faces of the image: no part of it lies inside the field of view "
                             "to give an organ surface",
                         "check the label map: this looks like a mask of the whole scan or the body, not of the " +
                             spec.name);

  // Sides cut flat: the tube's two ends, and any side where the label reaches the image border.
  for (int a = 0; a < 3; ++a) {
    const bool tube_axis = spec.model == OrganModel::tube && a == 2;
    p.cut[2 * a] = tube_axis || p.b0[a] == 0;
    p.cut[2 * a + 1] = tube_axis || p.b1[a] == N[a] - 1;
    static const char* names[3][2] = {{"first column (i = 0)", "last column"}, {"first row (j = 0)", "last row"},
                                      {"first slice (k = 0)", "last slice"}};
    if (p.b0[a] == 0) warnings.push_back(spec.name + " touches the image border at the " + names[a][0] + "; capped flat there");
    if (p.b1[a] == N[a] - 1) warnings.push_back(spec.name + " touches the image border at the " + names[a][1] + "; capped flat there");
  }

  // Band-limited to what the label carries: along each axis, σ is a fraction of the voxel spacing
  // (finer detail is the voxels' staircase), capped along thick-slice axes.
  const double sigma_mm_max = o.max_smoothing_sigma_mm;
  Eigen::Vector3d sigma_samples;
  const double coarsest_mm = std::max({s[0], s[1], s[2]});
  for (int a = 0; a < 3; ++a)
    sigma_samples[a] = std::min(o.smoothing_sigma_vox * (o.smoothing_isotropic ? coarsest_mm : s[a]), sigma_mm_max) / s[a];
  // The implicit domain runs this far past a cut plane before it ends (its rounded end is cut away).
  const double ext_mm = spec.wall_mm + 4.0 * o.edge_mm + 2.0;
  const double margin_mm = ext_mm + o.edge_mm + 3.0 * sigma_mm_max + 2.0;
  for (int a = 0; a < 3; ++a) {
    const std::int64_t m = std::int64_t(std::ceil(margin_mm / s[a])) + 2;
    p.lo[a] = p.b0[a] - m;
    p.n[a] = p.b1[a] - p.b0[a] + 1 + 2 * m;
  }

  // Crop; beyond a cut side the end layer is repeated so the surface runs straight through the
  // cut plane and the cut leaves a flat cap.
  const auto n = p.n;
  std::vector<std::uint8_t> mask(std::size_t(n[0] * n[1] * n[2]), 0);
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i) {
        std::array<std::int64_t, 3> src{p.lo[0] + i, p.lo[1] + j, p.lo[2] + k};
        bool inside_image = true;
        for (int a = 0; a < 3; ++a) {
          if (p.cut[2 * a] && src[a] < p.b0[a]) src[a] = p.b0[a];
          if (p.cut[2 * a + 1] && src[a] > p.b1[a]) src[a] = p.b1[a];
          if (src[a] < 0 || src[a] >= N[a]) inside_image = false;
        }
        if (inside_image && lm.labels[g.offset(src[0], src[1], src[2])] == spec.label)
          mask[std::size_t(i + n[0] * (j + n[1] * k))] = 1;
      }

  std::int64_t thin = 0;  // label voxels dropped as one voxel thin (not the copies past a cut side)
  const std::vector<std::int64_t> thin_voxels = o.drop_thin_voxels ? drop_one_voxel_thin(mask, n) : std::vector<std::int64_t>{};
  if (!thin_voxels.empty() && mask[std::size_t(thin_voxels.front())])
    throw MeshInputError(spec.name + " (label " + std::to_string(int(spec.label)) + ") is one voxel thin along an axis in " +
                             std::to_string(thin_voxels.size()) + " of its voxels, half of it or more (an organ found on one slice?): "
                             "no smooth surface at this grid carries it",
                         "check the segmentation of the " + spec.name + " on the slices next to it");
  if (o.drop_thin_voxels)
    for (const std::int64_t x : thin_voxels) {
      const std::int64_t c[3] = {p.lo[0] + x % n[0], p.lo[1] + (x / n[0]) % n[1], p.lo[2] + x / (n[0] * n[1])};
      bool label_voxel = true;
      for (int a = 0; a < 3; ++a) label_voxel = label_voxel && c[a] >= p.b0[a] && c[a] <= p.b1[a];
      thin += label_voxel;
    }
  if (thin > 0)
    warnings.push_back(spec.name + ": " + std::to_string(thin) + " voxel(s) (" + fmt(double(thin) * s.prod() / 1000.0) +
                       " ml) one voxel thin along an axis not meshed: no smooth surface at this grid carries them");
  // Largest component; then fill enclosed cavities (they would become inner shells).
  std::vector<std::int64_t> sizes;
  const auto comp = components(mask, n, sizes, true);
  const auto largest = std::int32_t(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
  for (std::size_t x = 0; x < mask.size(); ++x) mask[x] = comp[x] == largest;
  std::vector<std::int64_t> bg_sizes;
  const auto bg = components(mask, n, bg_sizes, false);
  std::vector<char> touches(bg_sizes.size(), 0);
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i)
        if (i == 0 || j == 0 || k == 0 || i == n[0] - 1 || j == n[1] - 1 || k == n[2] - 1) {
          const auto c = bg[std::size_t(i + n[0] * (j + n[1] * k))];
          if (c >= 0) touches[c] = 1;
        }
  std::int64_t filled = 0;
  for (std::size_t x = 0; x < mask.size(); ++x)
    if (bg[x] >= 0 && !touches[bg[x]]) mask[x] = 1, ++filled;
  if (filled > 0) warnings.push_back(spec.name + ": filled " + std::to_string(filled) + " enclosed voxel(s) (cavities)");

  // The voxels meshed, on the input grid (for volume and distance comparisons).
  const double voxel_mm3 = s.prod();
  std::array<std::int64_t, 3> klo{}, kn{};
  for (int a = 0; a < 3; ++a) {
    // Not beyond a cut side: the layers there are repeated copies, not label voxels.
    klo[a] = p.cut[2 * a] ? p.b0[a] : std::max<std::int64_t>(0, p.b0[a] - 1);
    kn[a] = (p.cut[2 * a + 1] ? p.b1[a] : std::min<std::int64_t>(N[a] - 1, p.b1[a] + 1)) - klo[a] + 1;
  }
  p.kept.grid = g;
  p.kept.grid.size_vox = kn;
  p.kept.grid.origin_lps_mm = g.index_to_lps_mm(Eigen::Vector3d(double(klo[0]), double(klo[1]), double(klo[2])));
  p.kept.labels.assign(std::size_t(kn[0] * kn[1] * kn[2]), 0);
  std::int64_t kept = 0;
  for (std::int64_t k = 0; k < kn[2]; ++k)
    for (std::int64_t j = 0; j < kn[1]; ++j)
      for (std::int64_t i = 0; i < kn[0]; ++i) {
        const std::int64_t ci = klo[0] + i - p.lo[0], cj = klo[1] + j - p.lo[1], ck = klo[2] + k - p.lo[2];
        if (mask[std::size_t(ci + n[0] * (cj + n[1] * ck))]) {
          p.kept.labels[std::size_t(i + kn[0] * (j + kn[1] * k))] = 1;
          ++kept;
        }
      }
  p.label_volume_mm3 = double(kept) * voxel_mm3;
  p.dropped_volume_mm3 = double(std::max<std::int64_t>(0, count - (kept - filled))) * voxel_mm3;
  if (const double apart_mm3 = p.dropped_volume_mm3 - double(thin) * voxel_mm3; apart_mm3 > 0.5 * voxel_mm3)
    warnings.push_back(spec.name + ": " + fmt(apart_mm3 / 1000.0) +
                       " ml outside the largest connected component not meshed");
  if (kept < 8)
    throw InputError(ExitCode::mesh_input,
                     spec.name + ": the label (value " + std::to_string(spec.label) + ") has only " +
                         std::to_string(kept) + " connected voxel(s), too few to mesh",
                     {}, "check the segmentation of the " + spec.name + "; meshing needs at least 8 voxels");

  // Smoothed field on the crop (grid frame: q = spacing ⊙ ijk).
  p.field.n = n;
  p.field.h = s;
  p.field.origin = Eigen::Vector3d(double(p.lo[0]), double(p.lo[1]), double(p.lo[2])).cwiseProduct(s);
  p.field.outside = 0.0f;
  p.field.v.assign(mask.begin(), mask.end());
  gaussian_smooth(p.field, sigma_samples);

  for (int a = 0; a < 3; ++a) {
    if (p.cut[2 * a]) p.clip.lo[a] = (double(p.b0[a]) - 0.5) * s[a];
    if (p.cut[2 * a + 1]) p.clip.hi[a] = (double(p.b1[a]) + 0.5) * s[a];
    p.extended.lo[a] = p.cut[2 * a] ? p.clip.lo[a] - ext_mm : -kInf;
    p.extended.hi[a] = p.cut[2 * a + 1] ? p.clip.hi[a] + ext_mm : kInf;
    p.domain.lo[a] = std::max(p.field.origin[a] + s[a], p.extended.lo[a] - s[a]);
    p.domain.hi[a] = std::min(p.field.upper()[a] - s[a], p.extended.hi[a] + s[a]);
  }

  // Iso-level whose enclosed volume (inside the clip box) equals the label's voxel volume:
  // the smoothing then moves the surface but does not shrink the organ.
  const double h = std::clamp(s.minCoeff() / 1.5, 0.25, std::min(0.5, o.edge_mm / 3.0));
  p.fine = resample(p.field, p.domain, h);
  std::vector<float> values;
  for (std::int64_t k = 0; k < p.fine.n[2]; ++k)
    for (std::int64_t j = 0; j < p.fine.n[1]; ++j)
      for (std::int64_t i = 0; i < p.fine.n[0]; ++i) {
        const Eigen::Vector3d q = p.fine.origin + Eigen::Vector3d(double(i), double(j), double(k)) * h;
        if ((q.array() >= p.clip.lo.array()).all() && (q.array() <= p.clip.hi.array()).all())
          values.push_back(p.fine.v[std::size_t(p.fine.index(i, j, k))]);
      }
  const auto want = std::int64_t(std::llround(p.label_volume_mm3 / (h * h * h)));
  if (want > 0 && want < std::int64_t(values.size())) {
    std::nth_element(values.begin(), values.begin() + (want - 1), values.end(), std::greater<float>());
    p.iso = std::clamp(values[std::size_t(want - 1)], 0.2f, 0.8f);
  }
  return p;
}

Eigen::Vector3d to_lps(const ImageGrid& g, const Eigen::Vector3d& q) { return g.origin_lps_mm + g.direction_lps * q; }

template <class M>
void transform_to_lps(const ImageGrid& g, M& mesh) {
  for (auto& v : mesh.vertices_lps_mm) v = to_lps(g, v);
}

bool inside(const Box& b, const Eigen::Vector3d& q) {
  return (q.array() >= b.lo.array()).all() && (q.array() <= b.hi.array()).all();
}

/// Most vertices a Mesh_3 run for an organ of `volume_mm3` may insert: ten times what the organ
/// filled with tetrahedra of edge `edge_mm` holds, and at least 20 000. A run that would pass it
/// is chasing a criterion it cannot meet (the facet distance along the rim where the field of
/// view cuts the organ, or along the creases of thick slices) and would run for hours.
std::size_t vertex_budget(double volume_mm3, double edge_mm) {
  return std::size_t(20000.0 + 10.0 * volume_mm3 / (edge_mm * edge_mm * edge_mm));
}

/// Runs `mesh` with the criteria; when it passes its vertex budget, again with the facet distance
/// doubled (`retries` times at most), saying so in `notes`. The last failure is rethrown.
template <class Fn>
auto with_looser_distance(Mesh3Criteria c, std::vector<std::string>& notes, const std::string& what, int retries,
                          Fn&& mesh) {
  for (int attempt = 0;; ++attempt) {
    try {
      return mesh(c);
    } catch (const MeshBudgetExceeded& e) {
      if (attempt == retries) throw;
      notes.push_back(what + ": Mesh_3 " + e.what() + "; remedied with the facet distance doubled");
      c.facet_distance_mm *= 2;
    }
  }
}

/// Tetrahedra inside a closed surface (grid frame; sharp rims protected), each tetrahedron's
/// region from `region_at` its centroid.
template <class RegionAt>
TetMesh polyhedral_with_regions(const SurfaceMesh& closed, Mesh3Criteria c, RegionAt&& region_at) {
  c.max_vertices = 0;  // the polyhedral domain follows the rims it protects
  TetMesh m = mesh3_tets_polyhedral(closed, 0, 80.0, c);
  for (std::size_t e = 0; e < m.tets.size(); ++e) {
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int v = 0; v < 4; ++v) centre += m.vertices_lps_mm[std::size_t(m.tets[e][std::size_t(v)])] / 4.0;
    m.region_ids[e] = region_at(centre);
  }
  return m;
}

SurfaceMesh make_surface(const LabelFunction& f, const Prepared& p, const MeshOptions& o, bool any_cut,
                         std::vector<std::string>& notes, Timeline& tl, const std::string& name) {
  Mesh3Criteria c;
  c.facet_size_mm = o.edge_mm;
  // The sampled surface is only the support the remeshing projects onto, so its facet distance
  // can be looser than the tetrahedra's (0.075 × edge). Phantom ground truth, one run each
  // (Mesh_3 seconds lumen / outer offset; trachea_lumen volume error, HD95; smallest angle of
  // gallbladder / lumen / wall; surfaces s):
  //   0.075 × edge: 0.58 / 0.62, −1.16 %, 0.301 mm, 38.8° / 29.8° / 29.8°, 2.6–3.5 s
  //   0.15  × edge: 0.32 / 0.53, −1.54 %, 0.327 mm, 32.0° / 29.3° / 27.5°, 2.37 s
  //   0.20  × edge: 0.28 / 0.54, −1.60 %, 0.335 mm, 36.0° / 26.6° / 26.6°, 2.0–2.6 s
  //   0.25  × edge: 0.34 / 0.46, −1.61 %, 0.339 mm, 36.3° / 29.8° / 30.1°, 2.2–2.3 s
  // (Facet size 1.3 × edge or facet angle 25° gained nothing; 3 or 4 remeshing iterations
  // instead of 6 left the lumen at 23° or gained nothing.) 0.15: half the lumen's sampling
  // time, the volume error still half of its 3 % bound, HD95 a tenth of the voxel diagonal.
  c.facet_distance_mm = 0.15 * o.edge_mm;
  c.facet_angle_deg = 30.0;
  c.max_vertices = vertex_budget(p.label_volume_mm3, o.edge_mm);
  SurfaceMesh s;
  {
    Timeline::Scope step{tl, name + ": Mesh_3"};
    try {
      s = with_looser_distance(c, notes, name, 2, [&](const Mesh3Criteria& cc) { return mesh3_surface(f, p.domain, cc); });
    } catch (const MeshBudgetExceeded& e) {
      throw MeshInputError(name + ": Mesh_3 " + e.what() + ", also with a looser facet distance",
                           "the organ's surface has creases no mesh of this edge length follows; try a larger "
                           "--edge-mm, or check the label map (thick slices, a flat slab)");
    }
  }
  if (any_cut) {
    Timeline::Scope step{tl, name + ": clip"};
    for (int a = 0; a < 3; ++a)
      if (p.cut[2 * a] || p.cut[2 * a + 1])
        s = clip_slab(s, a, p.cut[2 * a] ? p.clip.lo[a] : -1e9, p.cut[2 * a + 1] ? p.clip.hi[a] : 1e9);
  }
  RemeshParams rp;
  rp.target_edge_mm = o.edge_mm;
  rp.iterations = o.remesh_iterations;
  rp.feature_angle_deg = any_cut ? 60.0 : 0.0;
  rp.on_step = [&](const char* what, double seconds) {
    const double end = tl.now();
    tl.add(name + ": " + what, end - seconds, end);
  };
  return repair_and_remesh(s, rp, notes);
}

OrganMesh mesh_one(const LabelMap& lm, const MeshOrganSpec& spec, const MeshOptions& o, Progress& progress,
                   std::chrono::steady_clock::time_point started) {
  OrganMesh out;
  out.spec = spec;
  out.voxel_diagonal_mm = lm.grid.spacing_mm.norm();
  Timeline tl(started);
  const auto t0 = std::chrono::steady_clock::now();
  Prepared p;
  {
    Timeline::Scope step{tl, "prepare"};
    p = prepare(lm, spec, o, out.warnings);
  }
  out.label_volume_mm3 = p.label_volume_mm3;
  out.dropped_volume_mm3 = p.dropped_volume_mm3;
  progress.check_cancelled();
  const bool any_cut = std::any_of(p.cut.begin(), p.cut.end(), [](bool b) { return b; });
  const float iso = p.iso;
  const Field3& F = p.field;
  const Box ext = p.extended;

  const LabelFunction organ = [&](const Eigen::Vector3d& q) { return inside(ext, q) && F.sample(q) >= iso ? 1 : 0; };
  std::vector<std::string> notes;
  // The organ (or lumen) surface runs beside the distance field and the wall or body surface
  // built on it: two independent Mesh_3 runs, each sequential and seeded on its own thread.
  SurfaceMesh outer;
  Field3 sdf;
  const double t = spec.wall_mm;
  const Box clip = p.clip;
  std::vector<std::pair<std::string, SurfaceMesh>> extra;  // grid frame
  SurfaceMesh tube_wall, tube_outer;
  // A surface in LPS with its quality figures (compared with the label when `compare`).
  auto measured = [&](std::string name, SurfaceMesh m, bool compare) {
    transform_to_lps(lm.grid, m);
    Timeline::Scope step{tl, "measure " + name};
    NamedSurface ns{std::move(name), std::move(m), {}};
    // The fold gate looks at the organ's own boundary (where the label's staircase is), not at a
    // cut organ (its rims are meant to be sharp) nor at the inner wall: an offset inwards by the
    // wall folds by edge / (R − wall) where the organ folds by edge / R, a narrow neck's true
    // curvature at a coarse edge, not a staircase.
    SurfaceGuarantees g;
    if (compare && !any_cut && spec.model != OrganModel::tube) g.max_fold_deg = o.max_fold_deg;
    ns.quality = measure_surface(ns.mesh, o.edge_mm, g);
    if (compare) compare_with_label(ns.quality, ns.mesh, p.kept, 1, p.label_volume_mm3);
    return ns;
  };
  NamedSurface first, wall_measured;
  std::vector<std::string> inner_notes;
  tbb::parallel_invoke(
      [&] {
        outer = make_surface(organ, p, o, any_cut, notes, tl, spec.model == OrganModel::tube ? "lumen" : "surface");
        // Measured here, beside the other branch (a tube's lumen is measured beside the join).
        if (spec.model != OrganModel::tube) first = measured(spec.name, outer, true);
      },
      [&] {
        if (spec.model == OrganModel::solid) return;
        // The body lies inside the organ surface, the tube wall outside the lumen: one side each.
        {
          Timeline::Scope step{tl, "signed distance"};
          sdf = signed_distance(p.fine, iso, spec.model == OrganModel::tube ? DistanceSide::outside : DistanceSide::inside);
        }
        if (spec.model == OrganModel::wall_body) {
          const LabelFunction body = [&](const Eigen::Vector3d& q) { return inside(ext, q) && sdf.sample(q) <= -t ? 1 : 0; };
          bool has_body = false;
          for (float v : sdf.v) has_body |= v <= -t;
          if (has_body)
            extra.emplace_back(spec.name + "_wall_inner", make_surface(body, p, o, any_cut, inner_notes, tl, "inner wall"));
          else
            inner_notes.push_back("nowhere thicker than twice its " + fmt(t) + " mm wall: wall only, no body");
        } else if (spec.model == OrganModel::tube) {
          // Only the outer surface of the wall is sampled (its inside, the lumen and the
          // distance within wall_mm of it): the wall reuses the lumen surface as its inner tube.
          const LabelFunction offset = [&](const Eigen::Vector3d& q) { return inside(ext, q) && sdf.sample(q) <= t ? 1 : 0; };
          tube_outer = make_surface(offset, p, o, true, inner_notes, tl, "outer offset");
        }
      });
  if (spec.model == OrganModel::tube) {
    // The wall: outer tube + lumen turned inside out + annular caps between their rims. Sampling
    // the wall on its own (the way before) cost the trachea's critical path a second sampling and
    // remeshing of the lumen; it stays as the fallback should the two surfaces not join.
    std::vector<std::pair<int, double>> planes;
    for (int a = 0; a < 3; ++a) {
      if (p.cut[2 * a]) planes.emplace_back(a, p.clip.lo[a]);
      if (p.cut[2 * a + 1]) planes.emplace_back(a, p.clip.hi[a]);
    }
    RemeshParams rp;
    rp.target_edge_mm = o.edge_mm;
    rp.iterations = o.remesh_iterations;
    rp.on_step = [&](const char* what, double seconds) {
      const double end = tl.now();
      tl.add(what, end - seconds, end);
    };
    // The join and the wall's measurement are the trachea's critical path; the lumen is
    // measured beside them.
    tbb::parallel_invoke([&] { first = measured(spec.name + "_lumen", outer, true); },
                         [&] {
                           try {
                             Timeline::Scope step{tl, "join wall"};
                             tube_wall = tube_wall_from_surfaces(tube_outer, outer, planes, rp);
                           } catch (const std::exception& e) {
                             inner_notes.push_back(std::string("wall sampled on its own: ") + e.what());
                             const LabelFunction wall = [&](const Eigen::Vector3d& q) {
                               return inside(ext, q) && F.sample(q) < iso && sdf.sample(q) <= t ? 1 : 0;
                             };
                             tube_wall = make_surface(wall, p, o, true, inner_notes, tl, "wall (fallback)");
                           }
                           wall_measured = measured(spec.name + "_wall", tube_wall, false);
                         });
  }
  notes.insert(notes.end(), inner_notes.begin(), inner_notes.end());
  progress.check_cancelled();
  for (auto& n : notes) out.warnings.push_back(spec.name + ": " + n);
  out.seconds_surface = seconds_since(t0);
  progress.check_cancelled();

  // Tetrahedra.
  const auto t1 = std::chrono::steady_clock::now();
  if (o.tetrahedra) {
    Timeline::Scope step{tl, "tetrahedra"};
    Mesh3Criteria c;
    const double tet_edge_mm = o.tet_edge_mm > 0 ? o.tet_edge_mm : o.edge_mm;
    c.facet_size_mm = tet_edge_mm;
    c.facet_distance_mm = 0.075 * tet_edge_mm;
    c.facet_angle_deg = 25.0;
    c.cell_size_mm = tet_edge_mm;
    c.cell_radius_edge = o.max_radius_edge;
    // Sliver perturbation to 8°, exudation to 12°, then organsmith's repair (slides on the
    // surfaces, vertex moves, 2-3/3-2 flips, edge splits, peeling; tet_improve.cpp), which takes
    // every tet of the four reference inputs past the gate (figures there). Measured on the phantom ground truth (gallbladder; tets failing
    // the 10°/2 gate, smallest dihedral, Mesh_3 seconds): perturb 12° → 111 failing, 9.45°,
    // 12.6 s; 10° → 72, 9.45°, 10.5 s; 9° → 62, 9.01°, 6.4 s; 8° → 57, 8.04°, 1.5 s; none →
    // 36 below 10°, 4.9°. ODT and exude bounds above 12° changed nothing. The perturber's cost
    // grows steeply above 8° for few tets gained, so 8° it is.
    c.perturb_bound_deg = o.min_dihedral_deg - 2.0;
    c.exude_bound_deg = o.min_dihedral_deg + 2.0;
    // No time limit: a time-limited optimiser stops at a point that depends on the machine's
    // load, and the output would no longer be reproducible. Both stop by themselves.
    c.optimiser_seconds = 0.0;
    c.max_vertices = vertex_budget(p.label_volume_mm3, c.cell_size_mm);
    if (spec.model == OrganModel::tube) {
      // The cut ends' rims (inner and outer circle of each cap, a wall's thickness apart) are
      // protected with balls spaced at half the wall's thickness: balls of the tetrahedra's edge
      // on two rims closer than that must shrink to part, and the tiny, graded elements they
      // leave were every failing tetrahedron of the first mesh (phantom trachea, 4.5 mm
      // tetrahedra: 292 of 10 133 past the 10°/2 gate, all within 3 mm of a cap, shortest edge
      // 0.67 mm median). Spaced at t/2 the first mesh passes on the phantom and the real 8 mm
      // chest at tetrahedral edges 3, 4.5, 6 mm and the surface edge, surface edges 1.2–2 mm
      // (10 of 12; the two others within 2.07 of the ratio's 2), with a mesh stage 3–7 times
      // faster (no remedy to run): meshing/README.md "Tetrahedra".
      c.edge_size_mm = std::min(tet_edge_mm, 0.5 * t);
      out.volume = mesh3_tets_polyhedral(tube_wall, kRegionTracheaWall, 60.0, c);
      out.region_names[kRegionTracheaWall] = spec.name + "_wall";
    } else if (spec.model == OrganModel::wall_body) {
      const LabelFunction regions = [&](const Eigen::Vector3d& q) {
        if (!inside(clip, q) || F.sample(q) < iso) return 0;
        return sdf.sample(q) <= -t ? int(kRegionGallbladderBody) : int(kRegionGallbladderWall);
      };
      // A wall thinner than the tetrahedra cannot be resolved as a region of its own: meshing its
      // two interfaces would refine the whole organ down to the wall's thickness (phantom, 2 mm
      // wall: 3 mm tets 13 400 / 21 000 C3D10 nodes, 4.5 mm 8 800, 6 mm 46 700 as the mesher
      // chases both interfaces), and CalculiX spends ~2.7 s per iteration at 21 000 nodes. The
      // organ is then meshed as one solid, and each tetrahedron takes the region its centroid
      // lies in: the outer layer of elements is the wall (the centroid of a tetrahedron on the
      // surface lies about a quarter of its height inside), the rest the body.
      // tet_edge_mm = 0 (the surface edge) keeps the wall a layer of its own, as a pressure load
      // on its inner face needs.
      const bool wall_by_centroid = o.tet_edge_mm > 0 && tet_edge_mm > t;
      const auto wall_or_body = [&](const Eigen::Vector3d& q) {
        return sdf.sample(q) <= -t ? int(kRegionGallbladderBody) : int(kRegionGallbladderWall);
      };
      if (wall_by_centroid) {
        // These tetrahedra fill the organ's own gated surface (`outer`: remeshed, every gate
        // passed) rather than the label's implicit field. Sampled from the implicit field, the
        // label's voxel steps made Mesh_3 put clusters of tiny tetrahedra on the surface (phantom,
        // 6 mm tetrahedra: 1 161 of 6 790 with every edge below 1 mm, 191 below 0.1 mm; default
        // case, 4.5 mm: gates failed three times, 742 below 1 mm in the end), and CalculiX's
        // Newton steps diverged at those clusters. From the surface: none below 2 mm, the gates
        // pass at first, and the default case's solver model has 3 946 nodes instead of 9 946.
        out.warnings.push_back(spec.name + ": the " + fmt(t) + " mm wall is thinner than the " + fmt(tet_edge_mm) +
                               " mm tetrahedra; they fill the organ's surface and the outer layer of elements is the "
                               "wall (region by centroid)");
        out.volume = polyhedral_with_regions(outer, c, wall_or_body);
      } else {
        try {
          out.volume = with_looser_distance(c, out.warnings, spec.name + " tetrahedra", 1,
                                            [&](const Mesh3Criteria& cc) { return mesh3_tets_implicit(regions, p.domain, cc); });
        } catch (const MeshBudgetExceeded& e) {
          // The implicit domain rounds no rim: where the field of view cuts the organ, refinement
          // chases the sharp rim of the flat cap. The organ's own closed surface, with that rim
          // protected as a sharp feature, is meshed instead, and each tetrahedron takes the region
          // its centroid lies in (the wall/body boundary then follows the tetrahedra, within an
          // edge of the inner wall surface).
          out.warnings.push_back(spec.name + ": tetrahedra from its closed surface with sharp rims protected (" +
                                 e.what() + " in the implicit domain); the wall/body boundary follows the tetrahedra");
          out.volume = polyhedral_with_regions(outer, c, wall_or_body);
        }
      }
      out.region_names[kRegionGallbladderBody] = spec.name + "_body";
      out.region_names[kRegionGallbladderWall] = spec.name + "_wall";
    } else {
      const int region = kRegionSolidBase + spec.label;
      const LabelFunction solid = [&](const Eigen::Vector3d& q) { return inside(clip, q) && F.sample(q) >= iso ? region : 0; };
      try {
        out.volume = with_looser_distance(c, out.warnings, spec.name + " tetrahedra", 1, [&](const Mesh3Criteria& cc) {
          return mesh3_tets_implicit(solid, p.domain, cc);
        });
      } catch (const MeshBudgetExceeded& e) {
        out.warnings.push_back(spec.name + ": tetrahedra from its closed surface with sharp rims protected (" +
                               e.what() + " in the implicit domain)");
        out.volume = polyhedral_with_regions(outer, c, [&](const Eigen::Vector3d&) { return region; });
      }
      out.region_names[region] = spec.name;
    }
    const TetImproveStats fix = improve_tets(out.volume, o.min_dihedral_deg, o.max_radius_edge);
    if (fix.peeled_tets > 0)
      out.warnings.push_back(spec.name + ": removed " + std::to_string(fix.peeled_tets) +
                             " flat tetrahedra lying on the surface (below the quality gate)");
    transform_to_lps(lm.grid, out.volume);
    if (spec.model == OrganModel::tube && spec.rings.pitch_mm > 0) {
      split_tube_wall(out.volume, spec.rings);
      out.region_names.erase(kRegionTracheaWall);
      out.region_names[kRegionTubeCartilage] = spec.name + "_cartilage";
      out.region_names[kRegionTubeMembrane] = spec.name + "_membrane";
    }
    TetGuarantees tg;
    tg.min_dihedral_deg = o.min_dihedral_deg;
    tg.max_radius_edge = o.max_radius_edge;
    out.volume_quality = measure_tets(out.volume, tg);
  }
  out.seconds_tets = seconds_since(t1);

  // Surfaces to LPS, measured.
  auto add = [&](std::string name, SurfaceMesh m, bool compare) { out.surfaces.push_back(measured(std::move(name), std::move(m), compare)); };
  out.surfaces.push_back(std::move(first));
  for (auto& [name, m] : extra) add(name, std::move(m), false);
  if (spec.model == OrganModel::tube) out.surfaces.push_back(std::move(wall_measured));
  out.steps = tl.take();
  return out;
}

}  // namespace

std::size_t failure_count(const OrganMesh& m) {
  std::size_t n = m.volume_quality.failures.size();
  for (const auto& s : m.surfaces) n += s.quality.failures.size();
  return n;
}

std::string failure_text(const OrganMesh& m) {
  std::string t;
  for (const auto& s : m.surfaces)
    for (const auto& f : s.quality.failures) t += (t.empty() ? "" : "; ") + s.name + ": " + f;
  for (const auto& f : m.volume_quality.failures) t += (t.empty() ? "" : "; ") + m.spec.name + " tetrahedra: " + f;
  return t;
}

/// Meshes one organ; where a gate fails, tries the remedies in turn — a smoother iso-surface
/// (σ and its cap × 1.6: the staircase of thin or thick slices is what
/// leaves narrow triangles), a finer edge (× 0.8; a coarse polygon loses a thin tube's volume),
/// both, then other samplings of the smoother surface (a 1.25× edge; σ × 1.6 of the coarsest
/// spacing on every axis; σ × 2.56) — and keeps the
/// first mesh that passes every gate, else the one with the fewest failures. The gates that fail
/// after the first remedies are near misses that another sampling of the same surface clears (a
/// 1 mm-slice gallbladder: 18° triangles, 9.97° tetrahedra with σ × 1.6 and a 0.8× edge, every
/// gate passing at a 1.25× edge). What was tried, and which mesh was kept, is in its warnings.
OrganMesh mesh_with_remedies(const LabelMap& labels, const MeshOrganSpec& spec, const MeshOptions& options,
                             Progress& progress, std::chrono::steady_clock::time_point started) {
  OrganMesh best = mesh_one(labels, spec, options, progress, started);
  if (failure_count(best) == 0 || options.quality_remedies <= 0) return best;
  std::vector<std::string> tried{"gates failed at first (" + failure_text(best) + ")"};
  MeshOptions o = options;
  std::string kept = "the first mesh";
  struct Remedy {
    double sigma_factor, edge_factor;
    bool isotropic;
  };
  static constexpr Remedy kRemedies[] = {
      {1.6, 1.0, false}, {1.0, 0.8, false}, {1.6, 0.8, false}, {1.6, 1.25, false}, {1.6, 1.0, true}, {2.56, 1.0, false}};
  const int remedies = std::min<int>(options.quality_remedies, int(std::size(kRemedies)));
  for (int r = 0; r < remedies; ++r) {
    progress.check_cancelled();
    const Remedy& rem = kRemedies[r];
    const bool smoother = rem.sigma_factor > 1.0, other_edge = rem.edge_factor != 1.0;
    o.smoothing_sigma_vox = options.smoothing_sigma_vox * rem.sigma_factor;
    o.max_smoothing_sigma_mm = options.max_smoothing_sigma_mm * rem.sigma_factor;
    o.edge_mm = options.edge_mm * rem.edge_factor;
    o.smoothing_isotropic = rem.isotropic;
    std::string what = smoother ? std::string(rem.isotropic ? "isotropically " : "") + "smoother surface (σ " +
                                      fmt(o.smoothing_sigma_vox) + (rem.isotropic ? " coarsest voxel)" : " voxel)")
                                : std::string();
    if (other_edge) what += std::string(smoother ? " and " : "") + "edge " + fmt(o.edge_mm) + " mm";
    OrganMesh m;
    try {
      m = mesh_one(labels, spec, o, progress, started);
    } catch (const MeshInputError& e) {
      tried.push_back("remedy " + what + " failed: " + e.message());
      continue;
    }
    const std::size_t n = failure_count(m);
    tried.push_back("remedy " + what + ": " + (n == 0 ? std::string("every gate passes") : failure_text(m)));
    if (n < failure_count(best)) best = std::move(m), kept = "the remedy " + what;
    if (n == 0) break;
  }
  tried.push_back("kept " + kept);
  for (auto& t : tried) best.warnings.push_back(spec.name + ": " + t);
  // Last: tetrahedra of the surface edge (tet_edge_mm = 0) through the same remedies. A thin wall
  // under tetrahedra thicker than itself can fail every remedy on a coarse scan (phantom at 64²
  // and 10 mm slices, 2.5 mm trachea wall under 4.5 mm tetrahedra: 6 below 10°, 250 above
  // radius-edge 2) where the surface edge passes.
  if (failure_count(best) > 0 && options.tet_edge_mm > 0 && options.tet_edge_mm > options.edge_mm) {
    MeshOptions fine = options;
    fine.tet_edge_mm = 0;
    OrganMesh alt = mesh_with_remedies(labels, spec, fine, progress, started);
    if (failure_count(alt) < failure_count(best)) {
      alt.warnings.insert(alt.warnings.begin(), best.warnings.begin(), best.warnings.end());
      alt.warnings.push_back(spec.name + ": tetrahedra of the " + fmt(options.edge_mm) + " mm surface edge instead of " +
                             fmt(options.tet_edge_mm) + " mm ([stages.mesh] tet_edge_mm): " +
                             (failure_count(alt) == 0 ? std::string("every gate passes") : failure_text(alt)));
      return alt;
    }
  }
  return best;
}

OrganMeshes mesh_organs(const LabelMap& labels, const MeshOptions& options, Progress& progress) {
  if (labels.grid.voxel_count() == 0 || labels.labels.size() == 0)
    throw InputError(ExitCode::mesh_input, "the label map is empty (no voxels)", {}, "pass a segmented label map");
  if (options.edge_mm <= 0 || !std::isfinite(options.edge_mm))
    throw UsageError("the target edge length must be positive (got " + fmt(options.edge_mm) + " mm)");
  if (options.tet_edge_mm < 0 || !std::isfinite(options.tet_edge_mm))
    throw UsageError("the tetrahedron edge must be positive, or 0 for the surface edge (got " + fmt(options.tet_edge_mm) + " mm)");
  if (options.organs.empty())
    throw UsageError("no organ to mesh", "name the organs (label, mesh model, wall) from the organ registry");
  OrganMeshes result;
  std::vector<MeshOrganSpec> present;
  for (const auto& spec : options.organs) {
    if (labels.count(spec.label) > 0) {
      present.push_back(spec);
      continue;
    }
    const std::string msg = spec.name + ": label value " + std::to_string(spec.label) + " is not present in the label map";
    if (!options.skip_absent)
      throw InputError(ExitCode::mesh_input, msg, {}, "check the segmentation, or choose the organs to mesh");
    result.warnings.push_back(msg + "; not meshed");
  }
  if (present.empty())
    throw InputError(ExitCode::mesh_input, "none of the requested organs is present in the label map", {},
                     "the label map holds no voxel of any requested organ's label value; check --organ");

  // Edge length and wall against the data, before anything is allocated: an edge below a tenth of
  // a voxel or above a quarter of the organ's extent, or a wall of half the organ's extent or
  // more, asks for a mesh that cannot be made (or for unbounded memory and time).
  for (const auto& spec : present) {
    std::array<std::int64_t, 3> lo{labels.grid.size_vox[0], labels.grid.size_vox[1], labels.grid.size_vox[2]}, hi{-1, -1, -1};
    const auto& g = labels.grid;
    for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
      for (std::int64_t j = 0; j < g.size_vox[1]; ++j)
        for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
          if (labels.labels[g.offset(i, j, k)] == spec.label) {
            const std::array<std::int64_t, 3> ijk{i, j, k};
            for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], ijk[a]), hi[a] = std::max(hi[a], ijk[a]);
          }
    double largest = 0;
    for (int a = 0; a < 3; ++a) largest = std::max(largest, double(hi[a] - lo[a] + 1) * g.spacing_mm[a]);
    const double voxel = g.spacing_mm.minCoeff();
    if (options.edge_mm < 0.1 * voxel || options.edge_mm > 0.25 * largest)
      throw MeshInputError(spec.name + ": an edge length of " + fmt(options.edge_mm) + " mm does not fit the organ (" +
                               fmt(largest) + " mm across, voxels of " + fmt(voxel) + " mm)",
                           "choose an edge length from " + fmt(0.1 * voxel) + " to " + fmt(0.25 * largest) +
                               " mm (--edge-mm, [stages.mesh] edge_mm)");
    if (options.tet_edge_mm > 0 && (options.tet_edge_mm < 0.1 * voxel || options.tet_edge_mm > 0.25 * largest))
      throw MeshInputError(spec.name + ": a tetrahedron edge of " + fmt(options.tet_edge_mm) + " mm does not fit the organ (" +
                               fmt(largest) + " mm across, voxels of " + fmt(voxel) + " mm)",
                           "choose a tetrahedron edge from " + fmt(0.1 * voxel) + " to " + fmt(0.25 * largest) +
                               " mm ([stages.mesh] tet_edge_mm, --tet-edge-mm)");
    // Where the organ is nowhere thicker than twice its wall the wall is meshed alone (a warning
    // says so), so the wall is only refused when it could not fit across the organ at all.
    if (spec.model != OrganModel::solid && !(spec.wall_mm > 0 && spec.wall_mm < 0.5 * largest))
      throw MeshInputError(spec.name + ": a wall of " + fmt(spec.wall_mm) + " mm does not fit the organ (" +
                               fmt(largest) + " mm across)",
                           "give a wall below " + fmt(0.5 * largest) + " mm ([stages.mesh] wall_mm, --" + spec.name +
                               "-wall-mm)");
  }

  std::vector<OrganMesh> meshed(present.size());
  std::vector<std::exception_ptr> errors(present.size());
  progress.report(0.0, "meshing organs");
  const auto started = std::chrono::steady_clock::now();
  tbb::parallel_for(std::size_t(0), present.size(), [&](std::size_t i) {
    // Isolated: while this organ waits in its own nested parallel loops, its thread must not
    // pick up the other organ's task, which would reset and draw from the same thread's CGAL
    // random generator.
    tbb::this_task_arena::isolate([&] {
      try {
        meshed[i] = mesh_with_remedies(labels, present[i], options, progress, started);
      } catch (const MeshInputError& e) {  // name the organ: the deep steps do not know it
        errors[i] = std::make_exception_ptr(MeshInputError(present[i].name + ": " + e.message(), e.hint()));
      } catch (...) {
        errors[i] = std::current_exception();
      }
    });
  });
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
  progress.report(1.0, "meshing organs");
  result.organs = std::move(meshed);

  if (options.enforce_quality) {
    std::string failures;
    for (const auto& organ : result.organs) {
      for (const auto& s : organ.surfaces)
        for (const auto& f : s.quality.failures) failures += "\n  " + s.name + ": " + f;
      for (const auto& f : organ.volume_quality.failures) failures += "\n  " + organ.spec.name + " tetrahedra: " + f;
    }
    if (!failures.empty())
      throw MeshQualityError(
          "the meshes fail their quality guarantees" +
              std::string(options.quality_remedies > 0 ? " (also after meshing's remedies: smoother, finer, both, other samplings)" : "") +
              ":" + failures,
          "try another edge length (--edge-mm, or [stages.mesh] edge_mm), or pass --allow-quality-failures (in a case: "
          "[stages.mesh] quality_gate = \"report\") to write them anyway with the failures in quality.json");
  }
  return result;
}

}  // namespace organsmith
