#pragma once
// The gallbladder dissection path (thesis §5.2.3): the rim of the liver bed on the gallbladder
// surface. The bed comes from a liver label where one touches the organ, else from the CT itself
// (the part of the surface whose outside neighbourhood is liver parenchyma by intensity and
// texture, not fat, gas or bowel), else from the direction the liver usually lies in. Method and
// figures: HAPTICS.md ("Dissection path").
//
// All positions are LPS millimetres; intensities Hounsfield units.

#include "core/geometry.h"
#include "core/volume.h"

#include <Eigen/Core>

#include <cstdint>

#include <string>
#include <vector>

namespace organsmith::physics {

struct LiverBedOptions {
  /// The outside neighbourhood probed along each vertex normal, mm from the surface (default 3–5:
  /// beyond the wall and its partial-volume band, within the liver where the organ lies in its bed).
  double probe_near_mm = 3.0;
  double probe_far_mm = 5.0;
  /// σ of the Gaussian smoothing of the CT before the intensity test, mm (default 1.5: noise down,
  /// the liver edge kept).
  double smoothing_mm = 1.5;
  /// How far out from the surface the surroundings are surveyed for the liver's intensity, mm
  /// (default 25: the liver is the largest soft-tissue organ within this distance).
  double survey_mm = 25.0;
  /// Smallest liver − bile difference that lets intensity tell them apart, HU (default 10).
  double min_contrast_hu = 10.0;
  /// Smallest half-width of the liver's intensity band, HU (default 20); wider when the scan's
  /// parenchyma is noisier (2.5 robust standard deviations).
  double band_min_hu = 20.0;
  /// Radius of the opening that cuts thin bridges from the liver to touching bowel or vessels, mm
  /// (default 2; at least one voxel in each direction whose spacing is below 2 × this radius).
  double opening_mm = 2.0;
};

struct LiverBedEstimate {
  std::vector<double> score;      ///< per vertex: fraction of its outside probes that are liver (0–1)
  double bile_hu = 0.0;           ///< median just inside the surface
  double liver_hu = 0.0;          ///< the mode of the soft tissue surveyed around the organ
  double band_lo_hu = 0.0, band_hi_hu = 0.0;  ///< the band taken as parenchyma
  double liver_region_ml = 0.0;   ///< the connected parenchyma region found around the organ
  /// Empty when the estimate holds; else why the CT cannot tell the liver (then `score` is empty).
  std::string reason;
};

/// Per-vertex liver-bed score of a closed, outward-oriented gallbladder surface from the CT:
/// 1. bile = median of the smoothed CT 1–2.5 mm inside the surface; liver = the mode of the smoothed
///    CT sampled 2–survey_mm outside, above bile + min_contrast_hu (the liver is the largest
///    soft-tissue organ around the gallbladder, with or without contrast enhancement);
/// 2. parenchyma = smoothed CT within liver ± max(band_min_hu, 2.5 σ_robust), never below half way
///    to bile, opened (thin bridges to bowel walls and vessels cut), and the largest 6-connected
///    region of it around the organ (bowel loops, kidney and muscle that match the band are
///    smaller or separate);
/// 3. a vertex's score is the fraction of its probes probe_near_mm…probe_far_mm along the normal
///    that fall in that region.
/// Returns `reason` (and no score) when liver and bile differ by less than min_contrast_hu or no
/// parenchyma lies around the organ.
LiverBedEstimate liver_bed_from_ct(const SurfaceMesh& gallbladder, const Volume& ct, const LiverBedOptions& options = {});

/// Area-weighted vertex normals (unit; zero for an isolated vertex).
std::vector<Eigen::Vector3d> vertex_normals(const SurfaceMesh& mesh);

struct DissectionOptions {
  /// Label of the liver in the label map given (the organ registry's); 0 = none: the bed comes
  /// from the CT or the liver's direction.
  std::uint8_t liver_label = 0;
  double bed_distance_mm = 2.0;   ///< a surface point touching liver voxels within this distance is in the bed (default 2)
  /// Without a liver label, the bed is found in the CT when one is given (`ct`), else it is the
  /// part of the surface whose normal is within `bed_angle_deg` of `bed_direction_lps` (the liver
  /// lies superior and to the right of the gallbladder: LPS (−0.3, 0, 1)).
  bool bed_from_ct = true;
  LiverBedOptions ct;
  Eigen::Vector3d bed_direction_lps{-0.3, 0.0, 1.0};
  double bed_angle_deg = 60.0;
  /// σ of the smoothing of the bed over the surface and of the rim along its length, mm (default 2).
  double smoothing_mm = 2.0;
  double spacing_mm = 1.0;        ///< point spacing, mm (default 1)
  /// The path is smoothed along the surface until no turn exceeds this, degrees per mm of path
  /// (default 15: a hand following it turns at most a quarter circle over 6 mm).
  double max_turn_deg_per_mm = 15.0;
  /// …and until its total turning is at most this, degrees (default 720: a hand following the
  /// rim goes once around the bed; a loop that winds more is noise of the bed's edge).
  double max_total_turning_deg = 720.0;
  /// How far the smoothed path may leave the (faceted) surface, mm (default 0.5: below the
  /// facets' own deviation from the organ at a 2–3 mm edge).
  double surface_tolerance_mm = 0.5;
};

struct DissectionPath {
  Polyline line;                  ///< closed: the rim of the liver bed on the gallbladder surface
  /// "liver label", "CT intensity", or "surface facing the liver direction" (with the reason why
  /// neither the label nor the CT could be used, when one was given).
  std::string bed_source;
  double bed_area_mm2 = 0.0;      ///< area of the gallbladder surface in the bed
  double covered_fraction = 0.0;  ///< bed area / the whole gallbladder surface area
  double length_mm = 0.0;
  double max_surface_distance_mm = 0.0;  ///< largest distance of a point or segment midpoint to the surface
  /// Smallest distance between two parts of the path more than 3 mm apart along it: > 0 for a
  /// simple curve (no self-intersection).
  double min_self_distance_mm = 0.0;
  std::size_t rim_loops = 0;      ///< boundary loops of the bed before the longest was kept
  /// Sum of the angles between neighbouring segments, degrees (a convex plane loop: 360).
  double total_turning_deg = 0.0;
  /// Largest angle between neighbouring segments over their mean length, degrees per mm.
  double max_turn_deg_per_mm = 0.0;
  std::size_t smoothing_passes = 0;  ///< curvature-limited smoothing passes the path took
  double mean_drift_mm = 0.0, max_drift_mm = 0.0;  ///< distance of the smoothed path from the rim it was
  /// Per surface vertex: the smoothed bed score (the bed is ≥ 0.5).
  std::vector<double> vertex_score;
  LiverBedEstimate ct_estimate;   ///< the CT's figures when the bed came from (or was tried in) the CT
};

/// The liver bed on the gallbladder surface, per vertex: the score in [0, 1] (the bed is ≥ 0.5)
/// and where it came from. One rule for every user of the bed (the dissection path, the solver
/// model's fixed set): liver voxels of `liver`'s liver label within bed_distance_mm; else
/// `liver_bed_from_ct` on `ct`; else facing bed_direction_lps; smoothed over the surface
/// (σ = smoothing_mm).
struct LiverBedScore {
  std::vector<double> vertex_score;
  /// "liver label", "CT intensity", or "surface facing the liver direction" (with the reason why
  /// neither the label nor the CT could be used, when one was given).
  std::string source;
  LiverBedEstimate ct_estimate;   ///< the CT's figures when the bed came from (or was tried in) the CT
};
LiverBedScore liver_bed_score(const SurfaceMesh& gallbladder, const LabelMap* liver, const DissectionOptions& options = {},
                              const Volume* ct = nullptr);

/// The curve where the gallbladder wall meets the liver bed. Each vertex of the (closed,
/// outward-oriented) gallbladder surface gets a bed score in [0, 1] — liver voxels of `liver`'s
/// liver label within bed_distance_mm; else `liver_bed_from_ct` on `ct`; else facing
/// bed_direction_lps — the score is smoothed over the surface (σ = smoothing_mm) and the path is
/// its 0.5 iso-line (a piecewise-linear iso-line on a closed surface is a set of disjoint simple
/// loops): the longest loop, smoothed, resampled and snapped back onto the surface, then smoothed
/// along the surface (curve shortening, each point held within surface_tolerance_mm of
/// a smoothed copy of the surface) until no turn exceeds max_turn_deg_per_mm (at most 400
/// passes). Throws
/// InputError (exit code 60) when the bed is empty or covers the whole surface.
DissectionPath gallbladder_dissection_path(const SurfaceMesh& gallbladder, const LabelMap* liver,
                                           const DissectionOptions& options = {}, const Volume* ct = nullptr);

}  // namespace organsmith::physics
