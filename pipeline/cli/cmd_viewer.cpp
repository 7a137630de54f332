// Viewer subcommands: `snapshot` (off-screen PNG views of what a run left in its output
// directory) and `preview` (the interactive window with a mouse-driven tool).

#include "core/errors.h"
#include "physics/haptics/contact.h"
#include "physics/haptics/guidance.h"
#include "physics/haptics/haptic_loop.h"
#include "physics/materials/models.h"
#include "pipeline/cli/commands.h"
#include "pipeline/case/case_file.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "pipeline/stages/organ_fe.h"
#include "pipeline/review/output_scene.h"
#include "pipeline/run/runner.h"
#include "pipeline/run/terminal_progress.h"
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
                 const LoadFlags& flags, bool force) {
  SnapshotOptions options;
  if (!size.empty()) std::tie(options.width_px, options.height_px) = parse_size(size);
  if (!views.empty()) {
    options.views.clear();
    for (const auto& v : views) options.views.push_back(parse_view_kind(v));
  }
  const fs::path out = fs::absolute(out_arg);
  std::error_code ec;
  if (!fs::is_directory(out, ec))  // load_output_scene names what it misses inside the directory
    throw InputError(ExitCode::input_not_found, "no such output directory", out,
                     "run `organsmith run --out " + out_arg + "` first");
  // A run's directory: the run's snapshot stage itself, with the views and size given here.
  if (flags.ct.empty() && flags.labels.empty() && flags.calibration_dirs.empty())
    if (std::optional<CaseFile> c = case_of_run(out)) {
      if (!views.empty()) {
        for (const auto& v : views) parse_view_kind(v);  // an unknown view is a usage error
        c->stages.snapshot.views = views;
      }
      if (!size.empty()) std::tie(c->stages.snapshot.width_px, c->stages.snapshot.height_px) = parse_size(size);
      RunOptions ro;
      ro.from = "snapshot";
      ro.force = force;
      TerminalProgress progress;
      const RunSummary summary = run_case(*c, ro, progress);
      progress.finish();
      std::cout << "organsmith wrote " << summary.stages.back().outputs.size() << " snapshots ("
                << c->stages.snapshot.width_px << "x" << c->stages.snapshot.height_px << ") into "
                << OutputLayout{out}.snapshots_dir().string() << ":\n";
      for (const auto& o : summary.stages.back().outputs)
        std::cout << "  " << fs::path(o["path"].get<std::string>()).filename().string() << "\n";
      return 0;
    }
  OutputDir dir(out, OutputDirOptions{.in_place = true, .command = "snapshot"});
  TerminalProgress progress;
  OutputScene os;
  load_output_scene(out, flags, os, progress);
  for (const auto& m : os.missing) spdlog::info("not found: {}", m);
  const auto names = snapshot_view_names(os.scene, options);
  if (names.empty())
    throw InputError(ExitCode::input_not_found, "nothing to draw: no CT, label map or meshes found", out,
                     "run `organsmith run --out " + out_arg + "` first");
  const fs::path final_dir = OutputLayout{out}.snapshots_dir();
  std::vector<fs::path> written;
  dir.commit("snapshot", [&](const fs::path& staging) {
    fs::create_directories(OutputLayout{staging}.snapshots_dir());
    written = render_snapshots(os.scene, options, OutputLayout{staging}.snapshots_dir(), progress);
  });
  progress.finish();
  std::cout << "organsmith wrote " << written.size() << " snapshots (" << options.width_px << "x" << options.height_px
            << ") into " << final_dir.string() << ":\n";
  for (const auto& p : written) std::cout << "  " << p.filename().string() << "\n";
  return 0;
}

struct PreviewFlags {
  std::string out, size, path, mode = "mixed", screenshot, fe, fe_elements = "linear", trajectory;
  std::vector<double> start;
  double quit_after_s = 0;
  double rate_Hz = 1000.0;
  LoadFlags load;
  physics::ContactOptions contact;
};

int cmd_preview(const PreviewFlags& f) {
  PreviewOptions options;
  if (!f.size.empty()) std::tie(options.width_px, options.height_px) = parse_size(f.size);
  options.quit_after_s = f.quit_after_s;
  options.screenshot_png = f.screenshot;
  if (!f.start.empty()) {
    if (f.start.size() != 3) throw UsageError("--start takes three coordinates (LPS mm)", "e.g. --start 60,-20,-150");
    options.start_lps_mm = Eigen::Vector3d(f.start[0], f.start[1], f.start[2]);
  }
  options.on_event = [](const std::string& e) { std::cout << "preview: " << e << std::endl; };
  PreviewHaptics haptics;
  std::optional<physics::ScriptedDevice> hand_path;
  if (!f.trajectory.empty()) {
    hand_path.emplace(physics::ScriptedDevice::read_csv(f.trajectory));
    haptics.hand_path = &*hand_path;
  }
  haptics.loop.mode = physics::parse_force_mode(f.mode);
  haptics.loop.rate_Hz = f.rate_Hz;
  physics::validate(haptics.loop);
  physics::validate(f.contact);
  const fs::path out = fs::absolute(f.out);
  TerminalProgress progress;
  OutputScene os;
  LoadFlags lf = f.load;
  lf.need_ct = false;         // the window shows surfaces and paths only
  lf.context_step_vox = 0;    // organs only: translucent context costs the 30 fps on llvmpipe
  lf.plots = false;
  load_output_scene(out, lf, os, progress);
  progress.finish();
  for (const auto& m : os.missing) spdlog::info("not found: {}", m);
  if (os.scene.surfaces.empty())
    throw InputError(ExitCode::input_not_found, "nothing to show: no meshes and no label map", out,
                     "run `organsmith run --out " + f.out + "` first");

  const OrganRegistry registry = registry_of_output(out);
  // The guidance path: the one asked for, else the registry's preferred the run made.
  const ScenePath* chosen = nullptr;
  if (!f.path.empty()) {
    for (const auto& p : os.scene.paths)
      if (p.line.name == f.path) chosen = &p;
    if (!chosen) {
      std::string names;
      for (const auto& p : os.scene.paths) names += (names.empty() ? "" : ", ") + p.line.name;
      throw UsageError("no guidance path '" + f.path + "' in " + OutputLayout{out}.paths_dir().string(),
                       names.empty() ? "run `organsmith guide " + f.out + "` first" : "paths there: " + names);
    }
  } else {
    for (const auto& name : registry.preferred_path_names())
      for (const auto& p : os.scene.paths)
        if (!chosen && p.line.name == name) chosen = &p;
    if (!chosen && !os.scene.paths.empty()) chosen = &os.scene.paths.front();
  }
  std::optional<physics::PathIndex> path;
  if (chosen) {
    path.emplace(chosen->line);
    haptics.path = &*path;
    haptics.path_name = chosen->line.name;
  }

  // The contact surfaces: each organ's haptic surface of the registry (or, where the mesh stage
  // has not run, the organ's label-map surface), felt with its region's calibrated law.
  std::vector<SurfaceMesh> surfaces;
  std::vector<physics::StressTable> tables;
  std::string felt;
  // The organ felt and drawn through its real-time finite-element model (its solver file's mesh
  // on the corner nodes by default, laws and fixed set): the one asked for, else the gallbladder
  // where the mesh stage wrote it.
  std::unique_ptr<RealtimeOrgan> fe = fe_for_haptics(out, f.fe, f.contact.tool_radius_mm, f.fe_elements == "quadratic");
  const std::string fe_organ = fe ? fe->fe.organ : "none";
  if (fe) {
    haptics.tissue = fe->tissue.get();
    haptics.tissue_reaction = fe.get();
    haptics.tissue_triangles = fe->fe.surface_triangles;
    haptics.tissue_fixed_nodes = fe->fe.fixed_nodes;
    haptics.tissue_organ = fe_organ;
  }
  const std::optional<MaterialsFile> materials = read_materials(out);
  for (const auto& organ : registry.organs) {
    if (organ.haptic_surface.empty() || organ.name == fe_organ) continue;
    int best = -1;
    for (std::size_t i = 0; i < os.scene.surfaces.size(); ++i) {
      const SceneSurface& s = os.scene.surfaces[i];
      if (s.context || s.organ != organ.name) continue;
      if (s.name == organ.haptic_surface || best < 0) best = int(i);
    }
    if (best < 0) continue;
    const OutputRegionLaw law =
        output_region_law(materials ? &*materials : nullptr, organ.haptic_region, registry, OutputLayout{out}.materials());
    surfaces.push_back(os.scene.surfaces[best].mesh);
    tables.push_back(physics::StressTable::from_material(law.material, law.options, organ.haptic_max_strain));
    haptics.contact_scene_surfaces.push_back(best);
    felt += std::string(felt.empty() ? "" : ", ") + os.scene.surfaces[best].name + " (" + organ.haptic_region + ", " +
            law.material.model + (law.from_output ? "" : ", built-in preset") + ")";
  }
  std::unique_ptr<physics::ContactModel> contact;
  if (!surfaces.empty()) {
    contact = std::make_unique<physics::ContactModel>(physics::SurfaceIndex(std::move(surfaces)), std::move(tables),
                                                      f.contact);
    haptics.contact = contact.get();
  }
  spdlog::info("preview: haptic loop at {:.0f} Hz, mode {}; guidance path: {}; contact: {}", haptics.loop.rate_Hz,
               f.mode, chosen ? chosen->line.name : std::string("none (run `organsmith guide`)"),
               felt.empty() ? std::string("none") : felt);
  if (fe) {
    spdlog::info("preview: {} felt and drawn through its finite-element model ({} nodes, {} tetrahedra, {})", fe_organ,
                 fe->fe.mesh.nodes_mm.size(), fe->fe.mesh.elements.size(), fe->fe.inp.string());
    fe->tissue->start();
  }
  struct StopTissue {
    physics::RealtimeTissue* t;
    ~StopTissue() {
      if (t) t->stop();
    }
  } stop_tissue{fe ? fe->tissue.get() : nullptr};
  run_preview(os.scene, options, haptics);
  if (fe) {
    fe->tissue->stop();
    std::cout << "preview: fe " << fe->figures().dump() << std::endl;
  }
  return 0;
}

}  // namespace

std::vector<Command> viewer_commands(CLI::App& app) {
  std::vector<Command> commands;

  struct SnapshotArgs {
    std::string out, size;
    std::vector<std::string> views;
    LoadFlags load;
    bool force = false;
  };
  auto sa = std::make_shared<SnapshotArgs>();
  auto* snap = app.add_subcommand(
      "snapshot",
      "Render PNG views of what a run left in OUT_DIR into OUT_DIR/snapshots/ (replaced atomically):\n"
      "3D organ models, all organs with paths, axial/coronal/sagittal slices with the segmentation\n"
      "outline, tetrahedral cuts coloured by quality, plots of the calibrated tissue laws, Monte Carlo\n"
      "CDFs and calibration fits. Needs no display (starts a private Xvfb).");
  snap->add_option("OUT_DIR", sa->out, "output directory of `organsmith run`")->required();
  snap->add_flag("--force", sa->force, "redo the stage even when it is unchanged since the last run");
  snap->add_option("--views", sa->views, "views to render: organs overview slices tets plots (default: all)")
      ->delimiter(',');
  snap->add_option("--size", sa->size, "PNG size WIDTHxHEIGHT (default 1024x768)");
  snap->add_option("--ct", sa->load.ct, "CT to slice (default: OUT_DIR/phantom/dicom or the case's input)");
  snap->add_option("--calibration", sa->load.calibration_dirs,
                   "output directories of `organsmith calibrate` / `uncertainty --method mc` to plot (those under "
                   "OUT_DIR are found by themselves)")
      ->check(CLI::ExistingDirectory);
  snap->add_option("--labels", sa->load.labels,
                   "label map to outline (default: OUT_DIR/labels.nii.gz, else the phantom's ground truth)");
  commands.push_back({snap, [sa] { return cmd_snapshot(sa->out, sa->views, sa->size, sa->load, sa->force); }});

  auto pa = std::make_shared<PreviewFlags>();
  auto* prev = app.add_subcommand(
      "preview",
      "Open the interactive preview of OUT_DIR: organs, guidance paths and a tool proxy driven by the\n"
      "mouse through the 1 kHz haptic loop (guidance force toward the path, reaction force from the\n"
      "organs' calibrated laws). The gallbladder (--fe) is its real-time finite-element model: drawn as\n"
      "the model deforms under the tool, felt through its contact force; other organs dent. At the end\n"
      "the model's figures are printed (preview: fe {...}). Mouse motion moves the hand in\n"
      "the screen plane, the wheel in depth, left drag turns the view; keys 1/2/3 switch guidance-only,\n"
      "mixed and reaction-only forces; s prints the status; q quits.");
  prev->add_option("OUT_DIR", pa->out, "output directory of `organsmith run`")->required();
  prev->add_option("--size", pa->size, "window size WIDTHxHEIGHT (default 1024x768)");
  prev->add_option("--path", pa->path,
                   "guidance path in OUT_DIR/paths (default: the first the run made of an incision, a "
                   "dissection, a centreline, in the registry's organ order)");
  prev->add_option("--mode", pa->mode, "starting mode: guidance, mixed (default) or reaction")
      ->check(CLI::IsMember({"guidance", "mixed", "reaction"}));
  prev->add_option("--rate", pa->rate_Hz, "haptic loop rate in Hz (default 1000)")->check(CLI::Range(10.0, 10000.0));
  prev->add_option("--fe", pa->fe,
                   "organ felt and drawn through its real-time finite-element model (from meshes/<organ>/<organ>.inp); "
                   "none: every organ as a surface that dents (default: the gallbladder where its solver file exists)");
  prev->add_option("--fe-elements", pa->fe_elements,
                   "that model's elements: linear (the solver file's corner nodes: equilibria at the display rate, about "
                   "twice as stiff as CalculiX; default) or quadratic (its 10-node tets: CalculiX's answer, equilibria a "
                   "few times a second, the drawn organ and the force follow the tool by the last one's tangent between them)")
      ->check(CLI::IsMember({"linear", "quadratic"}));
  prev->add_option("--tool-radius-mm", pa->contact.tool_radius_mm, "radius of the tool tip sphere, mm (default 2)")
      ->check(CLI::PositiveNumber);
  prev->add_option("--labels", pa->load.labels, "label map to draw when there are no meshes");
  prev->add_option("--start", pa->start, "where the hand and tool start, LPS mm (x,y,z; default: beside the guidance path, else in front of the first organ)")
      ->delimiter(',');
  prev->add_option("--screenshot", pa->screenshot, "save the window as this PNG when it closes (with --quit-after: a picture for documents)");
  prev->add_option("--trajectory", pa->trajectory,
                   "a recorded hand path (CSV t_s,x,y,z; seconds from when the window opens, LPS mm; as `haptics "
                   "--trajectory` takes) moves the hand instead of the mouse: demonstrations, and the frame rate and "
                   "loop figures measured with the window drawing (bench/physics/realtime_tissue.sh)");
  prev->add_option("--quit-after", pa->quit_after_s, "close the window after this many seconds (0 = never)")
      ->check(CLI::NonNegativeNumber);
  commands.push_back({prev, [pa] { return cmd_preview(*pa); }});
  return commands;
}

}  // namespace organsmith
