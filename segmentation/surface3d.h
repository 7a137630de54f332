#pragma once
// A 3-D GVF deformable surface (Xu & Prince's gradient vector flow in 3-D; thesis ch. 3's
// variational framework with the surface as the level set φ = 0, φ < 0 inside). It starts from a
// mask (the slice-by-slice result) and evolves on the anisotropic grid in millimetres:
//   ∂φ/∂t = − F(x) |∇φ|              region: the point joins where its HU lies on the organ's side
//                                    of half-way between the means inside and outside the surface
//                                    near it (Chan–Vese's two-region term, localised as Lankton &
//                                    Tannenbaum do), F = 1 at the inside mean, −1 at the outside
//                                    mean, fading to 0 where the two differ by less than
//                                    min_contrast_hu (no wall seen: the image cannot tell); growth is
//                                    vetoed beyond half-way to the tissue past the organ's window and
//                                    halves at a HU gradient of edge_stop_hu_per_mm
//           − w_gvf v(x) · ∇φ        GVF of the 3-D edge map (normalised to |v| ≤ 1): onto walls
//           + ε w_c(x) κ |∇φ|        mean curvature, weighted by w_c = 1 / (1 + (Δ / c)²), Δ the
//                                    local inside/outside contrast: where a wall is seen the image
//                                    places the surface (an organ's small last section can be
//                                    reached), where none is the surface's shape does (a lobe
//                                    narrower than ≈ 2ε through a gap cannot grow out)
// The surface only adds to the start's core: the start opened by a ball of open_start_mm (a part
// of the start narrower than the ball, e.g. a lobe the slices took in through a gap, must be won
// again by the surface), and nothing farther than max_grow_mm from the start joins. Topology is
// kept simple: the component connected to the core, enclosed cavities filled, no hole through a
// slice.

#include "core/volume.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace organsmith::seg {

struct Surface3dOptions {
  double lo_hu = 0, hi_hu = 0;     ///< the organ's HU window (from the slices' pass)
  double ramp_hu = 8;              ///< HU over which the region speed goes from 0 to ±1
  double veto_widen = 1.5;         ///< growth stops beyond the window widened by this about its centre
  double region_sigma_mm = 1;      ///< smoothing of the HU before the region test, mm (per axis; skipped on an axis whose spacing is over 2σ)
  double edge_lo_hu = -150, edge_hi_hu = 150;  ///< HU window of the edge map
  double edge_sigma_mm = 1.5;      ///< smoothing of the edge map, mm
  /// The outward push is divided by 1 + (|∇I| / k)², |∇I| the HU gradient at edge_sigma_mm in
  /// HU/mm: it fades on walls (k = this; 0 = off).
  double edge_stop_hu_per_mm = 10;
  double gvf_mu = 0.2;             ///< GVF regularisation in in-plane pixel units (as the slices' GVF)
  int gvf_iterations = 80;         ///< explicit GVF steps
  double region_weight = 1.0;      ///< w_region, mm per unit time
  double gvf_weight = 0.5;         ///< w_gvf, mm per unit time at the strongest edge
  double curvature_mm = 1.0;       ///< ε, mm² per unit time
  bool stretch_slices = true;      ///< curvature across slices thicker than the pixels measured on slices stretched by that ratio
  double max_grow_mm = 10;         ///< farthest a point may lie from the start and join, mm
  double local_radius_mm = 6;      ///< half-size of the window of the local region statistics, mm (0 = the fixed window R alone)
  int local_min_slices = 3;        ///< …and at least this many slices either side (on thick slices a
                                   ///< window of one slice sees only the organ past its last section)
  double min_contrast_hu = 10;     ///< inside/outside mean difference below which the region speed fades, HU
  /// Curvature weight 1 / (1 + (Δ / this)²), Δ the local inside/outside contrast: where a wall is
  /// seen the image places the surface, where none is its shape does (0 = weight 1 everywhere).
  double contrast_curvature_hu = 0;
  double open_start_mm = 0;        ///< only the start opened by a ball of this radius is kept whatever the image says (0 = all of it)
  double margin_mm = 12;           ///< working box: the start's box grown by this, mm (at least 2 slices)
  int max_steps = 600;             ///< evolution steps at most
  bool parallel = true;            ///< slices of the box on TBB workers
};

/// A mask over a box of a grid (x fastest): what a surface needs of a 512² × 300 grid is the box
/// of a few dozen slices around the organ, not the whole grid's bytes.
struct BoxMask {
  std::array<std::int64_t, 3> origin_vox{};  ///< grid index of the box's first voxel
  std::array<std::int64_t, 3> size_vox{};    ///< voxels along x, y, z (all 0: empty)
  std::vector<std::uint8_t> inside;          ///< 1 = inside, over the box
  /// Inside at grid index (i, j, k); false outside the box.
  bool at(std::int64_t i, std::int64_t j, std::int64_t k) const;
  /// The mask over the whole grid `g` (the box must lie in it).
  std::vector<std::uint8_t> on_grid(const ImageGrid& g) const;
};

/// The voxels of `values` (g.voxel_count() of them, over the grid `g`) equal to `value`, in their
/// bounding box.
BoxMask box_mask_of(const std::uint8_t* values, const ImageGrid& g, std::uint8_t value);

struct Surface3dResult {
  BoxMask mask;                    ///< over the working box, 1 = inside the surface
  int steps = 0;                   ///< evolution steps taken
  bool converged = false;          ///< the inside stopped changing before max_steps
  std::int64_t start_voxels = 0, voxels = 0;
  std::int64_t first_k = 0, last_k = -1;  ///< slices the result spans
  double seconds = 0;
  std::int64_t box_voxels = 0;     ///< voxels of the working box
  double box_mib = 0;              ///< memory of the per-voxel arrays over the box, MiB
  std::string note;                ///< one line for segmentation.json
};

/// Evolves the surface from `start` (a box of the grid of `vol`, non-zero = inside). An empty
/// start gives an empty result. Deterministic for any thread count.
Surface3dResult evolve_surface3d(const Volume& vol, const BoxMask& start,
                                 const Surface3dOptions& options);

}  // namespace organsmith::seg
