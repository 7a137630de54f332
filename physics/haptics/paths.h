#pragma once
// Guidance paths (thesis §5.2.1, §5.2.3): the trachea centreline from its lumen, the anterior-wall
// incision path of the tracheal resection task, the gallbladder dissection path along the liver
// bed, a user's recorded path, and their JSON and VTP files. Methods and figures: HAPTICS.md.
//
// All positions are LPS millimetres.

#include "core/geometry.h"
#include "core/grid.h"
#include "core/volume.h"
#include "physics/haptics/dissection.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace organsmith::physics {

class SurfaceIndex;

/// Uniform resampling by arc length: the first and last points are kept and the spacing is
/// L / round(L / spacing_mm) (within half a step of the request). Closed polylines include the
/// closing segment. Throws InputError for an empty polyline or a non-positive spacing.
Polyline resample_polyline(const Polyline& line, double spacing_mm);

/// Gaussian smoothing along the arc length (σ in mm) of a polyline sampled at even spacing.
/// Open polylines keep their end points (odd reflection at the ends, which also keeps straight
/// ends straight); closed ones wrap around.
Polyline smooth_polyline(const Polyline& line, double sigma_mm);

// ---- trachea centreline --------------------------------------------------------------------------

struct CenterlineOptions {
  /// Label of the lumen in the label map (required; the organ registry's, e.g. the trachea's).
  std::uint8_t label = 0;
  std::string organ = "airway";   ///< the lumen's organ, as errors name it
  double spacing_mm = 1.0;         ///< output point spacing, mm (default 1)
  double smoothing_mm = 3.0;       ///< σ of the Gaussian smoothing along the line, mm (default 3)
  /// Exponent p of the medialness cost 1/(distance-to-wall)^p of the minimal path (default 2).
  double medial_power = 2.0;
};

struct Centerline {
  Polyline line;                         ///< from the cranial (superior) end to the caudal end
  std::vector<double> radius_mm;         ///< inscribed-sphere radius at each point (distance to the wall)
  /// How far each end was extended from the last voxel centre of the minimal path to the lumen
  /// boundary (cranial, caudal), mm.
  std::array<double, 2> end_extension_mm{0.0, 0.0};
};

/// Centreline of a tubular lumen (voxels == options.label; the largest connected part): the
/// minimal path between the centres of its two end caps (found along the principal axis) under
/// the cost 1/(distance to the wall)^p, so the path runs through the centres of the maximal
/// inscribed spheres; smoothed, extended along its end tangents to the lumen boundary (the
/// iso-surface half way between lumen and background voxels) so that it reaches both ends, and
/// resampled. Throws InputError (exit code 60) when the label is absent or too small, UsageError when
/// options.label is 0 (background).
Centerline trachea_centerline(const LabelMap& labels, const CenterlineOptions& options = {});

// ---- trachea incision path -----------------------------------------------------------------------

struct IncisionOptions {
  Eigen::Vector3d anterior_lps{0.0, -1.0, 0.0};  ///< the anterior direction (LPS: −y)
  double ring_pitch_mm = 6.0;   ///< cartilage ring period along the trachea, mm (default 6: ~18 rings over ~110 mm)
  int first_ring = 3;           ///< first ring of the resected segment, counted from 1 at the cranial end (default 3)
  int ring_count = 4;           ///< rings spanned (default 4)
  double spacing_mm = 1.0;      ///< point spacing, mm (default 1)
};

struct IncisionPath {
  Polyline line;
  double length_mm = 0.0;
  int first_ring = 0, last_ring = 0;        ///< 1-based, from the cranial end of the lumen
  double start_arc_mm = 0.0, end_arc_mm = 0.0;  ///< where it starts and ends along the centreline
  double max_wall_distance_mm = 0.0;        ///< largest distance of a point or segment midpoint to the wall
};

/// The incision line on the anterior outer wall surface: for each centreline station of the ring
/// segment, a ray from well in front of the trachea toward the centreline (along the anterior
/// direction made perpendicular to the centreline) meets the outer wall; the hits are resampled
/// and snapped onto the surface. `wall` must hold the trachea wall surface (surface 0 is used for
/// hits; other surfaces are ignored). Throws InputError when the ring segment lies beyond the
/// centreline or a ray misses the wall.
IncisionPath trachea_incision_path(const Centerline& centerline, const SurfaceIndex& wall,
                                   const IncisionOptions& options = {});

// ---- gallbladder dissection path: physics/haptics/dissection.h ----------------------------------

// ---- user paths and files ------------------------------------------------------------------------

/// Reads a recorded path: CSV with a header naming columns x, y, z (or x_mm, x_lps_mm, …; other
/// columns such as t_s are ignored) or JSON ({"points_lps_mm": [[x, y, z], …]} as organsmith
/// writes, or a bare array of triples). Throws InputError (exit code 3 when missing, 18 when
/// malformed: file and line named; fewer than 2 points; a non-finite coordinate).
Polyline read_path_file(const std::filesystem::path& path);
/// The same reader on a path's text; `path` names it in errors and gives the name when the text
/// has none (its stem).
Polyline read_path_text(const std::string& text, const std::filesystem::path& path);

/// Throws InputError (exit code 18) naming `source` when a point of `path` lies outside the
/// image's field of view by more than `tolerance_mm` (a path far outside the body).
void check_path_within(const Polyline& path, const ImageGrid& grid, const std::filesystem::path& source,
                       double tolerance_mm = 5.0);

/// JSON text of a path: name, coordinates, closed, length_mm, point_count, `properties` (numbers),
/// `notes` (texts; only when given), points_lps_mm and arc_length_mm (per point).
std::string path_json(const Polyline& path, const std::vector<std::pair<std::string, double>>& properties = {},
                      const std::vector<std::pair<std::string, std::string>>& notes = {});
/// VTK XML PolyData text: one line cell (closed paths repeat the first point id), point data
/// arc_length_mm.
std::string path_vtp(const Polyline& path);

}  // namespace organsmith::physics
