#pragma once
// The segment stage: the case's organs found in the CT (the GVF snakes of their segmentation
// presets) or taken from their label maps, written as labels.nii.gz, contours_<organ>.json and
// overlays/*.png. Run by `organsmith run` and `organsmith segment` (through the runner).

#include "core/progress.h"
#include "core/geometry.h"
#include "core/volume.h"
#include "pipeline/case/organ_registry.h"

#include <Eigen/Core>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace organsmith {

struct SegmentStageOrgan {
  std::string name;
  std::optional<Eigen::Vector3d> seed_lps_mm;  ///< as the ingest stage resolved it
  /// The case file gave the seed; a phantom's seed is a hint for reviewers only for an organ
  /// found without one.
  bool seed_from_case = false;
  std::filesystem::path label_map;  ///< take the organ from this label map (empty = segment it)
};

struct SegmentStageInputs {
  const Volume* ct = nullptr;               ///< required: the CT in HU
  std::vector<SegmentStageOrgan> organs;    ///< the case's organs, in order
  const OrganRegistry* registry = nullptr;  ///< required: labels, which organs need a seed
  std::string preset_overrides_toml;        ///< the case's [stages.segment.presets]
  std::string registry_toml;                ///< the case's registry file's text ("" = embedded)
};

/// What the stage hands on, as its files hold it (a resumed run reads the same back): the label
/// map with the grid of labels.nii.gz (single precision) and each segmented organ's contours as
/// contours_<organ>.json holds them (0.1 µm).
struct SegmentStageResult {
  LabelMap labels;
  std::vector<ContourStack> contours;
};

/// Segments into `staging`. InputError (exit 50s) when an organ is absent.
SegmentStageResult segment_stage(const SegmentStageInputs& in, const std::filesystem::path& staging, Progress& progress);

}  // namespace organsmith
