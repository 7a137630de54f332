// Viewer subcommands: `snapshot` (off-screen PNG views of what a run left in its output
// directory) and `preview` (the interactive window with a mouse-driven tool).

#include "core/errors.h"
#include "pipeline/commands.h"
#include "pipeline/image_io.h"
#include "pipeline/ingest.h"
#include "pipeline/output_scene.h"
#include "pipeline/runner.h"
#include "pipeline/terminal_progress.h"
#include "viewer/label_surface.h"
#include "viewer/mesh_files.h"
#include "viewer/preview.h"
#include "viewer/snapshot.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <fstream>
#include <iostream>
#include <optional>
#include <regex>
#include <set>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

std::pair<int, int> parse_size(const std::string& s) {
  static const std::regex re(R"((\d+)[xX](\d+))");
  std::smatch m;
  if (!std::regex_match(s, m, re)) throw UsageError("--size '" + s + "' is not WIDTHxHEIGHT", "e.g. --size 1024x768");
  return {std::stoi(m[1]), std::stoi(m[2])};
}

int cmd_snapshot(const std::string& out_arg, const std::vector<std::string>& views, const std::string& size,
                 const LoadFlags& flags) {
  SnapshotOptions options;
  if (!size.empty()) std::tie(options.width_px, options.height_px) = parse_size(size);
  if (!views.empty()) {
    options.views.clear();
    for (const auto& v : views) options.views.push_back(parse_view_kind(v));
  }
  const fs::path out = fs::absolute(out_arg);
  TerminalProgress progress;
  OutputScene os;
  load_output_scene(out, flags, os, progress);
  for (const auto& m : os.missing) spdlog::info("not found: {}", m);
  const auto names = snapshot_view_names(os.scene, options);
  if (names.empty())
    throw InputError(ExitCode::input_not_found, "nothing to draw: no CT, label map or meshes found", out,
                     "run `organsmith run --out " + out_arg + "` first");
  const fs::path final_dir = out / "snapshots";
  std::vector<fs::path> written;
  write_directory_atomically(final_dir, [&](const fs::path& staging) {
    written = render_snapshots(os.scene, options, staging, progress);
  });
  progress.finish();
  std::cout << "organsmith wrote " << written.size() << " snapshots (" << options.width_px << "x" << options.height_px
            << ") into " << final_dir.string() << ":\n";
  for (const auto& p : written) std::cout << "  " << p.filename().string() << "\n";
  return 0;
}

int cmd_preview(const std::string& out_arg, const std::string& size, double quit_after_s, const LoadFlags& flags) {
  PreviewOptions options;
  if (!size.empty()) std::tie(options.width_px, options.height_px) = parse_size(size);
  options.quit_after_s = quit_after_s;
  options.on_event = [](const std::string& e) { std::cout << "preview: " << e << std::endl; };
  TerminalProgress progress;
  OutputScene os;
  LoadFlags f = flags;
  f.need_ct = false;         // the window shows surfaces and paths only
  f.context_step_vox = 0;    // organs only: translucent context costs the 30 fps on llvmpipe
  load_output_scene(fs::absolute(out_arg), f, os, progress);
  progress.finish();
  for (const auto& m : os.missing) spdlog::info("not found: {}", m);
  if (os.scene.surfaces.empty())
    throw InputError(ExitCode::input_not_found, "nothing to show: no meshes and no label map", fs::absolute(out_arg),
                     "run `organsmith run --out " + out_arg + "` first");
  spdlog::info("preview: the tool is passive until the haptics stage lands (no force is computed)");
  run_preview(os.scene, options);
  return 0;
}

}  // namespace

std::vector<Command> viewer_commands(CLI::App& app) {
  std::vector<Command> commands;

  struct SnapshotArgs {
    std::string out, size;
    std::vector<std::string> views;
    LoadFlags load;
  };
  auto sa = std::make_shared<SnapshotArgs>();
  auto* snap = app.add_subcommand(
      "snapshot",
      "Render PNG views of what a run left in OUT_DIR into OUT_DIR/snapshots/ (replaced atomically):\n"
      "3D organ models, all organs with paths, axial/coronal/sagittal slices with the segmentation\n"
      "outline, tetrahedral cuts coloured by quality. Needs no display (starts a private Xvfb).");
  snap->add_option("OUT_DIR", sa->out, "output directory of `organsmith run`")->required();
  snap->add_option("--views", sa->views, "views to render: organs overview slices tets plots (default: all)")
      ->delimiter(',');
  snap->add_option("--size", sa->size, "PNG size WIDTHxHEIGHT (default 1024x768)");
  snap->add_option("--ct", sa->load.ct, "CT to slice (default: OUT_DIR/phantom/dicom or the case's input)");
  snap->add_option("--labels", sa->load.labels,
                   "label map to outline (default: OUT_DIR/labels.nii.gz, else the phantom's ground truth)");
  commands.push_back({snap, [sa] { return cmd_snapshot(sa->out, sa->views, sa->size, sa->load); }});

  struct PreviewArgs {
    std::string out, size;
    double quit_after_s = 0;
    LoadFlags load;
  };
  auto pa = std::make_shared<PreviewArgs>();
  auto* prev = app.add_subcommand(
      "preview",
      "Open the interactive preview of OUT_DIR: organs, paths and a tool proxy. The mouse moves the\n"
      "tool (wheel: depth; left drag turns the view); keys 1/2/3 switch guidance-only, mixed and\n"
      "reaction-only modes; q quits. The tool is passive until the haptics stage lands.");
  prev->add_option("OUT_DIR", pa->out, "output directory of `organsmith run`")->required();
  prev->add_option("--size", pa->size, "window size WIDTHxHEIGHT (default 1024x768)");
  prev->add_option("--labels", pa->load.labels, "label map to draw when there are no meshes");
  prev->add_option("--quit-after", pa->quit_after_s, "close the window after this many seconds (0 = never)")
      ->check(CLI::NonNegativeNumber);
  commands.push_back({prev, [pa] { return cmd_preview(pa->out, pa->size, pa->quit_after_s, pa->load); }});
  return commands;
}

}  // namespace organsmith
