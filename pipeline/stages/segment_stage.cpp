#include "pipeline/stages/segment_stage.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "pipeline/io/image_io.h"
#include "pipeline/output/output_layout.h"
#include "segmentation/segment.h"

#include <spdlog/spdlog.h>

namespace organsmith {

namespace fs = std::filesystem;

SegmentStageResult segment_stage(const SegmentStageInputs& in, const fs::path& staging, Progress& progress) {
  std::vector<OrganRequest> requests;
  for (const SegmentStageOrgan& o : in.organs) {
    if (!o.label_map.empty()) continue;
    OrganRequest r;
    r.organ = o.name;
    r.seed_lps_mm = o.seed_lps_mm;
    // An organ found automatically ignores a phantom seed (a hint for reviewers only).
    if (!in.registry->at(r.organ).needs_seed && !o.seed_from_case) r.seed_lps_mm.reset();
    requests.push_back(std::move(r));
  }
  SegmentOptions options;
  options.preset_overrides_toml = in.preset_overrides_toml;
  options.registry_toml = in.registry_toml;
  SegmentationResult result = segment_organs(*in.ct, requests, options, progress);
  for (const SegmentStageOrgan& o : in.organs) {
    if (o.label_map.empty()) continue;
    const OrganInfo& info = in.registry->at(o.name);
    const double ml = merge_organ_from_label_map(result.labels, read_label_map(o.label_map), info.label);
    if (ml <= 0)
      throw InputError(ExitCode::organ_not_found,
                       "organ " + o.name + " (label " + std::to_string(info.label) + ") is absent from its label map",
                       o.label_map, "check the label map and the organ's label in the organ registry");
    spdlog::info("segment: {} {:.1f} ml from the label map {}", o.name, ml, o.label_map.filename().string());
  }
  const OutputLayout staged{staging};
  write_label_map(result.labels, staged.labels());
  // Later stages get the grid the file holds (single precision), as a resumed run reads it.
  result.labels.grid = read_image_grid(staged.labels());
  SegmentStageResult out;
  for (const auto& organ : result.organs) {
    const std::string text = contours_json(organ);
    write_file_atomic(staged.contours(organ.organ), text);
    if (auto stack = contours_from_json(text, organ.organ)) out.contours.push_back(std::move(*stack));
    spdlog::info("segment: {} {:.1f} ml on slices {}–{}", organ.organ, organ.volume_ml, organ.first_slice,
                 organ.last_slice);
    for (const auto& note : organ.notes) spdlog::info("segment: {}: {}", organ.organ, note);
  }
  fs::create_directories(staged.overlays_dir());
  write_overlays(*in.ct, result, staged.overlays_dir());
  out.labels = std::move(result.labels);
  return out;
}

}  // namespace organsmith
