#pragma once
// Organ presets: HU windows, snake parameters and anatomical size limits per organ. The defaults
// are the `segment` tables of the organ registry data/organs.toml (embedded at build time, with
// the sources of its numbers); a case file may override any key or add organs.

#include <cstdint>
#include <map>
#include <string>
#include <string_view>

namespace organsmith {

struct OrganPreset {
  std::string organ;
  std::uint8_t label = 0;
  bool needs_seed = true;
  double seed_hu_lo = -30, seed_hu_hi = 40;   ///< HU range a seed's neighbourhood must have
  double seed_radius_mm = 4;                  ///< radius of that neighbourhood, mm
  double region_below_hu = 50, region_above_hu = 22;  ///< pressure window around the organ mean, HU
  double air_hu = -500;                       ///< lumen threshold (airways), HU
  double pressure_ramp_hu = 8;                ///< HU over which the pressure goes from 0 to ±1
  double region_sigma_mm = 2;                 ///< smoothing before the region test, mm (at least)
  double region_sigma_px = 0;                 ///< …and at least this many pixels
  double region_noise_hu = 0;                 ///< …and enough to bring the image's noise below this, HU; 0 = off
  double region_noise_max_sigma_mm = 2;       ///< …but never more than this for the noise, mm (anatomy, not noise, below it)
  double region_open_mm = 0;                  ///< radius of the opening that removes thin partial-volume bands, mm
  double region_open_fraction = 0;            ///< …at least this fraction of the organ's equivalent radius
  double edge_window_lo_hu = -150, edge_window_hi_hu = 150;
  double edge_sigma_mm = 1.5;
  double neck_ratio = 0;                      ///< cut necks narrower than this × the smaller lobe's diameter; 0 = off
  double neck_depth_mm = 2;                   ///< …with at least one end this deep in a concavity, mm
  double seat_band_mm = 0;                    ///< final GVF-only pass moves the contour at most this far; 0 = off
  double seat_sigma_mm = 0.7;                 ///< smoothing of the HU profile it follows, mm
  double seat_outside_mm = 2.0;               ///< where "outside" is sampled beyond the band, mm
  double seat_min_contrast_hu = 20;           ///< no seating where the outside differs less from the organ
  double min_edge_support = 0;                ///< propagation stops when a smaller fraction of the contour has a visible wall outside it
  double edge_stop = 0;                       ///< edge-map value (0–1) at which the outward pressure halves; 0 = off
  double min_area_mm2 = 15, max_area_mm2 = 2600;  ///< per-slice lumen/organ area limits, mm²
  double max_area_ratio = 1.8;                ///< largest area ratio between neighbouring slices
  /// A section larger than shift_growth_ratio × the previous one with more than
  /// max_shifted_fraction of its area farther than shift_tolerance_mm outside the previous
  /// contour ends the organ (a neighbour joined in). max_shifted_fraction = 1 turns this off.
  /// A seed whose section is too small to fit starts from the nearest slice within this distance
  /// (mm) where the organ fits (0 = only the seed's slice).
  double seed_slide_mm = 0.0;
  /// A result shorter than this along the slices (mm) also tries the starts on the slices within
  /// seed_slide_mm and keeps the longest (0 = never).
  double min_extent_mm = 0.0;
  /// Airway: a second air component under the lumen this far back (mm) also marks the carina.
  double divide_span_mm = 0.0;
  /// Airway: one air component whose parts stay apart after an erosion of this fraction of the
  /// slice thickness (two lobes joined by a neck narrower than twice that) is the divided lumen
  /// seen through a thick slice's partial volume. 0 = off.
  double divide_neck_slice_fraction = 0.0;
  double shift_growth_ratio = 1.25;
  double max_shifted_fraction = 1.0;
  double shift_tolerance_mm = 3.0;
  /// The next slice starts from the part of a section within shift_tolerance_mm of the section
  /// before, where that part holds at least this fraction of its area (0 = from the whole section).
  double guide_core_fraction = 0.0;
  double area_ratio_span_mm = 3;              ///< …and between slices this far apart, mm (thin slices)
  double max_mean_drift_hu = 25;              ///< propagation stops beyond this drift of the mean
  double min_fill = 0.55, max_aspect = 2.2;   ///< roundness tests of airway candidates
  double max_midline_offset_mm = 40;          ///< airway candidates: distance from the body midline
  double min_length_mm = 20;                  ///< airway candidates: shortest run along the body
  double start_radius_mm = 3;                 ///< radius of the initial snake, mm
  double roi_margin_mm = 30;                  ///< margin of the per-slice working window, mm
  double max_length_mm = 140;                 ///< seeded organs: longest extent from the seed along the slices, mm
  double region_reach_mm = 3;                 ///< seeded organs: the 3-D region continues a slice where it lies within this of the previous contour, mm
  /// Seeded organs: a slice whose section leaked is fitted again with the pressure held within
  /// continuity_margin_mm + continuity_slope × the slice spacing of the previous section (moved
  /// by the organ's drift); at most max_held_in_a_row such slices in a row (0 mm = never).
  double continuity_margin_mm = 0, continuity_slope = 0;
  int max_held_in_a_row = 1;
  double max_pinned_fraction = 1.0;           ///< …and only where at most this fraction of the held contour rests on the reach's limit
  double max_pinned_fraction_walled = 0.0;    ///< …or at most this fraction, where the held contour has its wall seen around…
  double min_walled_edge_support = 1.0;       ///< …at least this fraction of it (edge support)
  double alpha = 0.6, beta = 0.3, kappa = 0.4, balloon = 0.5;  ///< snake (see SnakeOptions)
  double point_spacing_mm = 1.5;
  double gvf_mu = 0.2;
  int max_iterations = 300;
  /// Seeded organs: a 3-D GVF surface (segmentation/surface3d.h) evolved from the slices' result;
  /// false = the slices' result is the label.
  bool surface3d = false;
  double surface3d_max_grow_mm = 10;   ///< …farthest a point may lie from the slices' result and join, mm
  double surface3d_curvature_mm = 1;   ///< …ε of the curvature term, mm
  double surface3d_gvf_weight = 0.5;   ///< …weight of the GVF term against the region term (1)
  double surface3d_edge_stop_hu_per_mm = 10;  ///< …HU gradient at which the outward push halves, HU/mm (0 = off)
  int surface3d_max_steps = 600;       ///< …evolution steps at most
  double surface3d_local_radius_mm = 6;   ///< …half-size of the local inside/outside statistics' window, mm (0 = window only)
  double surface3d_min_contrast_hu = 10;  ///< …inside/outside contrast below which the region speed fades, HU
  double surface3d_contrast_curvature_hu = 0;  ///< …contrast at which the curvature weight halves, HU (0 = weight 1)
  double surface3d_open_start_mm = 0;     ///< …only the slices' result opened by a ball this wide is kept whatever the image says, mm
};

/// The embedded data/organs.toml (the organ registry; each organ's preset is its `segment` table).
std::string_view default_organ_presets_toml();

/// How preset text is laid out.
enum class PresetText {
  overrides,  ///< one table per organ holding preset keys (`segment --presets`, a case's overrides)
  registry,   ///< the organ registry: label and needs_seed on the organ, the preset in [<organ>.segment]
};

/// Parses presets from TOML text. Tables and keys absent from `text` keep the values in `base`.
/// Throws CaseFileError naming the key when a value has the wrong type or a key is unknown.
std::map<std::string, OrganPreset> parse_organ_presets(std::string_view text,
                                                       std::map<std::string, OrganPreset> base = {},
                                                       PresetText form = PresetText::overrides);

/// The embedded presets (parsed once per call; cheap).
std::map<std::string, OrganPreset> default_organ_presets();

}  // namespace organsmith
