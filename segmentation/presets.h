#pragma once
// Organ presets: HU windows, snake parameters and anatomical size limits per organ. Every number is
// in the organ registry data/organs.toml (embedded at build time, with the sources of its
// numbers): its [segment_defaults] table, and each organ's `segment` table for what differs; the
// fields below hold none of their own. A case file may override any key or add organs.

#include <cstdint>
#include <map>
#include <string>
#include <string_view>

namespace organsmith {

struct OrganPreset {
  std::string organ;
  std::uint8_t label{};
  bool needs_seed = true;
  /// How the organ is found: "seeded" (from the seed, slice to slice both ways) or "airway"
  /// (without a seed: the most cranial round midline air lumen, followed caudally).
  std::string driver;
  double seed_hu_lo{}, seed_hu_hi{};          ///< HU range a seed's neighbourhood must have
  double seed_radius_mm{};                    ///< radius of that neighbourhood, mm
  double region_below_hu{}, region_above_hu{}; ///< pressure window around the organ mean, HU
  double air_hu{};                            ///< lumen threshold (airways), HU
  double pressure_ramp_hu{};                  ///< HU over which the pressure goes from 0 to ±1
  double region_sigma_mm{};                   ///< smoothing before the region test, mm (at least)
  double region_sigma_px{};                   ///< …and at least this many pixels
  double region_noise_hu{};                   ///< …and enough to bring the image's noise below this, HU; 0 = off
  double region_noise_max_sigma_mm{};         ///< …but never more than this for the noise, mm (anatomy, not noise, below it)
  double region_open_mm{};                    ///< radius of the opening that removes thin partial-volume bands, mm
  double region_open_fraction{};              ///< …at least this fraction of the organ's equivalent radius
  double edge_window_lo_hu{}, edge_window_hi_hu{};
  double edge_sigma_mm{};
  double neck_ratio{};                        ///< cut necks narrower than this × the smaller lobe's diameter; 0 = off
  double neck_depth_mm{};                     ///< …with at least one end this deep in a concavity, mm
  double seat_band_mm{};                      ///< final GVF-only pass moves the contour at most this far; 0 = off
  double seat_sigma_mm{};                     ///< smoothing of the HU profile it follows, mm
  double seat_outside_mm{};                   ///< where "outside" is sampled beyond the band, mm
  double seat_min_contrast_hu{};              ///< no seating where the outside differs less from the organ
  double min_edge_support{};                  ///< propagation stops when a smaller fraction of the contour has a visible wall outside it
  double edge_stop{};                         ///< edge-map value (0–1) at which the outward pressure halves; 0 = off
  double min_area_mm2{}, max_area_mm2{};      ///< per-slice lumen/organ area limits, mm²
  double max_area_ratio{};                    ///< largest area ratio between neighbouring slices
  /// A section larger than shift_growth_ratio × the previous one with more than
  /// max_shifted_fraction of its area farther than shift_tolerance_mm outside the previous
  /// contour ends the organ (a neighbour joined in). max_shifted_fraction = 1 turns this off.
  /// A seed whose section is too small to fit starts from the nearest slice within this distance
  /// (mm) where the organ fits (0 = only the seed's slice).
  double seed_slide_mm{};
  /// A result shorter than this along the slices (mm) also tries the starts on the slices within
  /// seed_slide_mm and keeps the longest (0 = never).
  double min_extent_mm{};
  /// Airway: a second air component under the lumen this far back (mm) also marks the carina.
  double divide_span_mm{};
  /// Airway: one air component whose parts stay apart after an erosion of this fraction of the
  /// slice thickness (two lobes joined by a neck narrower than twice that) is the divided lumen
  /// seen through a thick slice's partial volume. 0 = off.
  double divide_neck_slice_fraction{};
  double shift_growth_ratio{};
  double max_shifted_fraction{};
  double shift_tolerance_mm{};
  /// The next slice starts from the part of a section within shift_tolerance_mm of the section
  /// before, where that part holds at least this fraction of its area (0 = from the whole section).
  double guide_core_fraction{};
  double area_ratio_span_mm{};                ///< …and between slices this far apart, mm (thin slices)
  double max_mean_drift_hu{};                 ///< propagation stops beyond this drift of the mean
  double min_fill{}, max_aspect{};            ///< roundness tests of airway candidates
  double max_midline_offset_mm{};             ///< airway candidates: distance from the body midline
  double min_length_mm{};                     ///< airway candidates: shortest run along the body
  double start_radius_mm{};                   ///< radius of the initial snake, mm
  double roi_margin_mm{};                     ///< margin of the per-slice working window, mm
  double max_length_mm{};                     ///< seeded organs: longest extent from the seed along the slices, mm
  double region_reach_mm{};                   ///< seeded organs: the 3-D region continues a slice where it lies within this of the previous contour, mm
  /// Seeded organs: a slice whose section leaked is fitted again with the pressure held within
  /// continuity_margin_mm + continuity_slope × the slice spacing of the previous section (moved
  /// by the organ's drift); at most max_held_in_a_row such slices in a row (0 mm = never).
  double continuity_margin_mm{}, continuity_slope{};
  int max_held_in_a_row{};
  double max_pinned_fraction{};               ///< …and only where at most this fraction of the held contour rests on the reach's limit
  double max_pinned_fraction_walled{};        ///< …or at most this fraction, where the held contour has its wall seen around…
  double min_walled_edge_support{};           ///< …at least this fraction of it (edge support)
  double alpha{}, beta{}, kappa{}, balloon{}; ///< snake (see SnakeOptions)
  double point_spacing_mm{};
  double gvf_mu{};
  int max_iterations{};
  /// Seeded organs: a 3-D GVF surface (segmentation/surface3d.h) evolved from the slices' result;
  /// false = the slices' result is the label.
  bool surface3d{};
  double surface3d_max_grow_mm{};             ///< …farthest a point may lie from the slices' result and join, mm
  double surface3d_curvature_mm{};            ///< …ε of the curvature term, mm
  double surface3d_gvf_weight{};              ///< …weight of the GVF term against the region term (1)
  double surface3d_edge_stop_hu_per_mm{};     ///< …HU gradient at which the outward push halves, HU/mm (0 = off)
  int surface3d_max_steps{};                  ///< …evolution steps at most
  double surface3d_local_radius_mm{};         ///< …half-size of the local inside/outside statistics' window, mm (0 = window only)
  double surface3d_min_contrast_hu{};         ///< …inside/outside contrast below which the region speed fades, HU
  double surface3d_contrast_curvature_hu{};   ///< …contrast at which the curvature weight halves, HU (0 = weight 1)
  double surface3d_open_start_mm{};           ///< …only the slices' result opened by a ball this wide is kept whatever the image says, mm
};

/// The embedded data/organs.toml (the organ registry; each organ's preset is its `segment` table).
std::string_view default_organ_presets_toml();

/// The registry's table of the values every organ's preset starts from (not an organ).
inline constexpr std::string_view kSegmentDefaultsTable = "segment_defaults";

/// The embedded registry's [segment_defaults]: where every organ's preset starts.
OrganPreset segment_defaults();

/// How preset text is laid out.
enum class PresetText {
  overrides,  ///< one table per organ holding preset keys (`segment --presets`, a case's overrides)
  registry,   ///< the organ registry: label and needs_seed on the organ, the preset in [<organ>.segment]
};

/// Parses presets from TOML text. Tables and keys absent from `text` keep the values in `base`; an
/// organ new to `base` starts from the registry's [segment_defaults] (in registry form, the text's
/// own such table where it has one, over the embedded one).
/// Throws CaseFileError naming the key when a value has the wrong type or a key is unknown.
std::map<std::string, OrganPreset> parse_organ_presets(std::string_view text,
                                                       std::map<std::string, OrganPreset> base = {},
                                                       PresetText form = PresetText::overrides);

/// The embedded presets (parsed once per call; cheap).
std::map<std::string, OrganPreset> default_organ_presets();

}  // namespace organsmith
