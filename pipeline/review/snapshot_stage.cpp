#include "pipeline/review/snapshot_stage.h"

#include "pipeline/output/output_layout.h"
#include "pipeline/review/output_scene.h"
#include "pipeline/stages/organ_fe.h"
#include "viewer/snapshot.h"

#include <spdlog/spdlog.h>

namespace organsmith {

namespace fs = std::filesystem;

void snapshot_stage(const SnapshotStageInputs& in, const SnapshotStageOptions& options, const fs::path& staging,
                    Progress& progress) {
  LoadFlags flags;
  flags.ct = in.ct_path.string();
  flags.registry = in.registry;
  flags.case_name = in.case_name;
  flags.organs = in.organs;
  flags.ct_volume = in.ct;
  flags.label_map = in.labels;
  flags.meshes = in.meshes;
  flags.phantom_truth = in.phantom_truth;
  flags.contours = in.contours;
  flags.paths = in.paths;
  flags.materials = in.materials;
  OutputScene os;
  load_output_scene(in.out_dir, flags, os, progress);
  for (const auto& m : os.missing) spdlog::info("snapshot: not found: {}", m);
  const fs::path dir = OutputLayout{staging}.snapshots_dir();
  fs::create_directories(dir);
  SnapshotOptions so;
  so.width_px = options.width_px;
  so.height_px = options.height_px;
  so.views.clear();
  for (const auto& v : options.views) so.views.push_back(parse_view_kind(v));
  const auto written = render_snapshots(os.scene, so, dir, progress);
  spdlog::info("snapshot: {} views", written.size());
  for (const auto& organ : options.indent) {
    // The organ under the simulate stage's probe, through organsmith's FE model of its solver file.
    IndentOptions io;
    io.fe.quadratic = true;
    io.realtime_press = false;
    io.picture_png = dir / ("indent_" + organ + ".png");
    io.picture_width_px = so.width_px;
    io.picture_height_px = so.height_px;
    const nlohmann::json r = haptics_indent(in.out_dir, organ, io, progress);
    spdlog::info("snapshot: indent_{}.png ({} mN at {} mm)", organ, 1e3 * r["curve"].back()[1].get<double>(),
                 r["curve"].back()[0].get<double>());
  }
}

}  // namespace organsmith
