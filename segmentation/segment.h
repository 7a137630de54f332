#pragma once
// The segmentation stage: gallbladder (seeded) and trachea (found automatically) by GVF snakes,
// slice by slice, on the axial slices of a Volume (k = slice index). Thesis §2.3 and §5.1.6;
// Xu & Prince 1998.

#include "core/errors.h"
#include "core/geometry.h"
#include "core/progress.h"
#include "core/volume.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

/// One organ to segment. The gallbladder needs exactly one seed inside it (LPS mm, or voxel
/// index); the trachea needs none.
struct OrganRequest {
  std::string organ;                                    ///< "gallbladder" or "trachea"
  std::optional<Eigen::Vector3d> seed_lps_mm;           ///< DICOM patient coordinates, mm
  std::optional<std::array<std::int64_t, 3>> seed_ijk;  ///< voxel index (i, j, k)
};

struct SegmentOptions {
  /// TOML overriding the embedded organ presets (data/organs.toml), e.g. a case file's
  /// [segmentation.presets] table re-serialised; empty = the embedded defaults.
  std::string preset_overrides_toml;
  /// Organ-registry TOML (the form of data/organs.toml) adding or changing organs, applied before
  /// the overrides: a case's own registry file; empty = the embedded registry only.
  std::string registry_toml;
  bool parallel = true;  ///< organs, propagation directions and slices on TBB workers (default true)
};

/// What was found for one organ.
struct OrganSegmentation {
  std::string organ;
  std::uint8_t label = 0;
  ContourStack contours;           ///< one contour per slice, LPS mm, counter-clockwise in (i, j)
  std::int64_t first_slice = 0;    ///< lowest slice index k with a contour
  std::int64_t last_slice = -1;    ///< highest
  double volume_ml = 0;            ///< voxels carrying `label`
  std::optional<Eigen::Vector3d> seed_lps_mm;  ///< the seed used (given, or found for the trachea)
  std::vector<std::string> notes;  ///< why propagation stopped at each end, etc.
  /// Seeded organs: the HU window and region smoothing the slices settled on (the 3-D surface's
  /// region term uses them); 0/0 for organs found otherwise.
  double window_lo_hu = 0, window_hi_hu = 0, region_sigma_mm = 0;
};

struct SegmentationResult {
  LabelMap labels;                          ///< on the input grid: 0 background, preset labels (1 gallbladder, 2 trachea)
  std::vector<OrganSegmentation> organs;    ///< in request order
};

/// A seed or organ that cannot be used. Exit codes: ExitCode::bad_seed, ExitCode::organ_not_found.
class SegmentationError : public Error {
 public:
  SegmentationError(ExitCode code, std::string message, std::string hint = {})
      : Error(code, std::move(message), {}, std::move(hint)) {}
};

/// Segments the requested organs. Throws SegmentationError for a seed outside the image or
/// outside the organ's HU range (air, fat, bone…), an unknown organ, or an organ that cannot be
/// found (no label is then produced: the result is never empty or the whole image silently),
/// and Cancelled when `progress` asks. Deterministic for any thread count.
SegmentationResult segment_organs(const Volume& volume, const std::vector<OrganRequest>& organs,
                                  const SegmentOptions& options, Progress& progress);

/// The contour stack as JSON text: {"organ", "frame": "LPS", "unit": "mm", "contours":
/// [{"slice_k", "points_lps_mm": [[x, y, z], …]}]}.
std::string contours_json(const OrganSegmentation& organ);
/// The reader of that text (contours_<organ>.json): the stack as the text holds it; nothing when
/// the text is not JSON or not in that form (`why`, when given, says what is wrong with a
/// contour of an otherwise well-formed file).
std::optional<ContourStack> contours_from_json(const std::string& text, const std::string& organ,
                                               std::string* why = nullptr);

struct OverlayOptions {
  double window_lo_hu = -200;   ///< grey-level window of the slices, HU (default −200)
  double window_hi_hu = 250;    ///< (default 250)
  int max_tiles = 24;           ///< slices per organ montage (evenly sampled; default 24)
  double tile_mm = 90;          ///< side of each tile around the organ, mm (default 90)
  int tile_px = 240;            ///< side of each tile in pixels (default 240)
};

/// Writes, per organ, `overlay_<organ>.png`: a montage of slices (cropped around the organ,
/// upsampled) with the contour drawn, slice index in each tile; and `overlay_<organ>_full.png`,
/// the whole middle slice. Throws OutputError when a file cannot be written.
void write_overlays(const Volume& volume, const SegmentationResult& result, const std::filesystem::path& dir,
                    const OverlayOptions& options = {});

}  // namespace organsmith
