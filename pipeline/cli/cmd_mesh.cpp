// `mesh` subcommand: label map → organ surfaces, wall bodies and tetrahedral meshes, written in
// every simulator format with a quality.json per organ (meshing/mesh.h, meshing/export.h).

#include "core/errors.h"
#include "core/format.h"
#include "meshing/export.h"
#include "meshing/mesh.h"
#include "physics/materials/presets.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/cli/commands.h"
#include "pipeline/stages/mesh_stage.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/case/case_file.h"
#include "pipeline/io/image_io.h"
#include "pipeline/run/runner.h"
#include "pipeline/run/terminal_progress.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <memory>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

struct MeshFlags {
  std::string input, out;
  double edge_mm = 0.0;  // 0 = not given: 1.5, or the run's [stages.mesh] edge_mm
  double tet_edge_mm = -1.0;  // < 0 = not given: 4.5, or the run's [stages.mesh] tet_edge_mm
  std::string formats;   // empty = not given: all, or the run's formats
  bool ras = false;
  bool force = false;  // `mesh DIR`: redo the stage even when unchanged
  std::vector<std::string> organs;  // NAME or NAME=LABEL
  std::vector<std::string> wall_mm;  // ORGAN=MM; an organ not named keeps the organ registry's wall
  bool no_tets = false, allow_failures = false;
  bool material_band = false;
  double max_fold_deg = -1.0;  // < 0 = not given: the default (60), or the run's [stages.mesh] max_fold_deg
};

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string item;
  std::istringstream in(s);
  while (std::getline(in, item, sep))
    if (!item.empty()) out.push_back(item);
  return out;
}

/// --wall-mm ORGAN=MM, each naming an organ of `registry` with a wall and a positive thickness.
std::map<std::string, double> wall_flags(const MeshFlags& f, const OrganRegistry& registry) {
  std::map<std::string, double> walls;
  for (const auto& item : f.wall_mm) {
    const auto eq = item.find('=');
    const std::string name = item.substr(0, eq);
    const OrganInfo* info = registry.find(name);
    std::string walled;
    for (const auto& o : registry.organs)
      if (o.mesh == OrganMeshModel::wall_body || o.mesh == OrganMeshModel::tube) walled += (walled.empty() ? "" : ", ") + o.name;
    if (eq == std::string::npos || name.empty())
      throw UsageError("--wall-mm " + item + ": write ORGAN=MM", "e.g. --wall-mm gallbladder=3 (organs with a wall: " + walled + ")");
    if (!info || (info->mesh != OrganMeshModel::wall_body && info->mesh != OrganMeshModel::tube))
      throw UsageError("--wall-mm " + item + ": '" + name + "' is no organ with a wall", "organs with a wall: " + walled);
    double mm = 0.0;
    std::size_t used = 0;
    const std::string value = item.substr(eq + 1);
    try {
      mm = std::stod(value, &used);
    } catch (...) {
      used = 0;
    }
    if (used == 0 || used != value.size() || !std::isfinite(mm) || !(mm > 0))
      throw UsageError("--wall-mm " + item + ": the thickness must be a positive number of millimetres",
                       "e.g. --wall-mm " + name + "=" + format_g(info->wall_mm, 3) + " (the registry's)");
    walls[name] = mm;
  }
  return walls;
}

std::vector<MeshOrganSpec> organ_specs(const MeshFlags& f) {
  const OrganRegistry& registry = builtin_organ_registry();
  const std::map<std::string, double> walls = wall_flags(f, registry);
  std::vector<MeshOrganSpec> specs;
  for (const auto& name : registry.modelled()) specs.push_back(mesh_spec(registry.at(name), walls));
  if (f.organs.empty()) return specs;
  std::vector<MeshOrganSpec> chosen;
  for (const auto& item : f.organs) {
    const auto eq = item.find('=');
    const std::string name = item.substr(0, eq);
    MeshOrganSpec spec{name, 0, OrganModel::solid, 0.0};
    for (const auto& d : specs)
      if (d.name == name) spec = d;
    if (eq != std::string::npos) {
      int v = -1;
      try {
        v = std::stoi(item.substr(eq + 1));
      } catch (...) {
      }
      if (v < 1 || v > 255) throw UsageError("--organ " + item + ": the label value must be 1–255", "e.g. --organ trachea=1");
      spec.label = std::uint8_t(v);
    } else if (spec.label == 0) {
      throw UsageError("--organ " + name + " needs its label value", "write it as NAME=LABEL, e.g. --organ liver=3");
    }
    chosen.push_back(spec);
  }
  return chosen;
}


/// `mesh DIR`: the mesh and attach stages of the run (or `segment`) that wrote DIR, with its case's
/// options and the flags given here: the same files as `organsmith run` writes.
int continue_run(const MeshFlags& f) {
  if (!f.out.empty() && fs::weakly_canonical(fs::absolute(f.out)) != fs::weakly_canonical(fs::absolute(f.input)))
    throw UsageError("`mesh DIR` writes into DIR (DIR/meshes/)", "drop --out, or give a label map file to mesh elsewhere");
  if (!f.organs.empty())
    throw UsageError("--organ applies to a label map file", "`mesh DIR` meshes the organs of DIR's case");
  std::optional<CaseFile> run = case_of_run(f.input);
  if (!run)
    throw InputError(ExitCode::input_not_found, "the directory holds no run", OutputLayout{f.input}.manifest(),
                     "give a label map file, or the directory `organsmith segment` or `run` wrote");
  CaseFile& c = *run;
  MeshStageOptions& m = c.stages.mesh;
  if (f.edge_mm > 0) m.edge_mm = f.edge_mm;
  if (f.tet_edge_mm >= 0) m.tet_edge_mm = f.tet_edge_mm;
  if (!f.formats.empty()) m.formats = split(f.formats, ',');
  if (f.ras) m.ras = true;
  if (f.no_tets) m.tetrahedra = false;
  if (f.material_band) m.material_band = true;
  if (f.max_fold_deg >= 0) m.max_fold_deg = f.max_fold_deg;
  for (const auto& [organ, mm] : wall_flags(f, c.registry)) m.wall_mm[organ] = mm;
  m.quality_gate = f.allow_failures ? "report" : "enforce";
  {
    const auto known = all_mesh_formats();
    for (const auto& x : m.formats)
      if (std::find(known.begin(), known.end(), x) == known.end())
        throw UsageError("unknown mesh format '" + x + "'", "choose from stl, obj, ply, vtp, vtu, msh, msh22, inp, feb");
  }
  RunOptions ro;
  ro.from = "mesh";
  ro.force = f.force;
  ro.until = "attach";
  TerminalProgress progress;
  const RunSummary summary = run_case(c, ro, progress);
  progress.finish();
  spdlog::info("meshes and materials written into {} (meshes/, materials.json)", summary.out_dir.string());
  return 0;
}

int run_mesh(const MeshFlags& f) {
  const auto t0 = std::chrono::steady_clock::now();
  if (!fs::exists(f.input)) throw InputError(ExitCode::input_not_found, "the label map does not exist", f.input);
  if (fs::is_directory(f.input)) return continue_run(f);
  if (f.out.empty()) throw UsageError("--out is required with a label map file", "e.g. --out meshes");
  OutputDir out(f.out, OutputDirOptions{.inputs = {f.input}, .command = "mesh"});
  const LabelMap labels = read_label_map(f.input);
  MeshStageOptions options;  // the run's defaults, with the flags given
  if (f.edge_mm > 0) options.edge_mm = f.edge_mm;
  if (f.tet_edge_mm >= 0) options.tet_edge_mm = f.tet_edge_mm;
  if (!f.formats.empty()) options.formats = split(f.formats, ',');
  options.ras = f.ras;
  options.tetrahedra = !f.no_tets;
  options.quality_gate = f.allow_failures ? "report" : "enforce";
  options.material_band = f.material_band;
  if (f.max_fold_deg >= 0) options.max_fold_deg = f.max_fold_deg;
  {  // reject unknown formats before spending time on meshing
    const auto known = all_mesh_formats();
    for (const auto& x : options.formats)
      if (std::find(known.begin(), known.end(), x) == known.end())
        throw UsageError("unknown mesh format '" + x + "'", "choose from stl, obj, ply, vtp, vtu, msh, msh22, inp, feb");
  }
  // The gallbladder's liver bed (its fixed set) from the label map's liver label where it has
  // one, else the liver's usual direction (no CT here; `run` also looks in the CT).
  MeshStageInputs in;
  in.labels = &labels;
  in.labels_file = f.input;
  in.organs = organ_specs(f);
  in.registry = &builtin_organ_registry();
  for (const auto& spec : in.organs)
    if (in.registry->find(spec.name)) in.band_organs.push_back(spec.name);

  TerminalProgress progress;
  const fs::path final_dir = out.path();
  OrganMeshes meshes;
  out.commit("mesh", [&](const fs::path& staging) { meshes = mesh_stage(in, options, staging, progress); });
  progress.finish();
  for (const auto& organ : meshes.organs) {
    for (const auto& s : organ.surfaces) {
      const auto& q = s.quality;
      std::string line = fmt::format("{:<24} {:>7} triangles, edges within ±25 %: {:.1f} %, min angle {:.1f}°", s.name,
                                     q.triangles, 100 * q.edge_within_tolerance, q.angle_min_deg);
      if (q.reference_volume_mm3 > 0)
        line += fmt::format(", volume {:+.2f} %, HD95 {:.2f} mm", 100 * q.volume_error, q.hd95_mm);
      spdlog::info("{}{}", line, q.ok() ? "" : "  FAILS: " + q.failures.front());
    }
    if (!organ.volume.tets.empty())
      spdlog::info("{:<24} {:>7} tetrahedra, min dihedral {:.1f}°, max radius-edge {:.2f}{}", organ.spec.name + " (volume)",
                   organ.volume_quality.tets, organ.volume_quality.dihedral_min_deg, organ.volume_quality.radius_edge_max,
                   organ.volume_quality.ok() ? "" : "  FAILS: " + organ.volume_quality.failures.front());
  }
  spdlog::info("meshes written to {} in {:.2f} s", final_dir.string(),
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return 0;
}

}  // namespace

std::vector<Command> meshing_commands(CLI::App& app) {
  auto flags = std::make_shared<MeshFlags>();
  auto* sub = app.add_subcommand(
      "mesh", "label map → organ surfaces, wall bodies and tetrahedral meshes (STL OBJ PLY VTP VTU MSH INP FEB)");
  sub->add_option("LABELS", flags->input,
                  "label map (.nii/.nii.gz/.nrrd/.mha), or the directory of `organsmith segment`/`run` to continue "
                  "(its mesh and attach stages, into DIR/meshes/ and DIR/materials.json)")
      ->required();
  sub->add_option("--out", flags->out,
                  "output directory for a label map file: new, empty, or one organsmith wrote before (its earlier "
                  "outputs are replaced; other files are never touched)");
  sub->add_option("--edge-mm", flags->edge_mm, "target surface edge length in mm (default 1.5)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--tet-edge-mm", flags->tet_edge_mm,
                  "edge of the tetrahedral meshes (solver files) in mm; 0 = the surface edge (default 4.5: solver\n"
                  "models of ~10 000–16 000 nodes)")
      ->check(CLI::Range(0.0, 20.0));
  sub->add_option("--formats", flags->formats, "comma-separated: stl,obj,ply,vtp,vtu,msh,msh22,inp,feb (default: all)");
  sub->add_flag("--ras", flags->ras, "write RAS coordinates instead of LPS");
  sub->add_flag("--force", flags->force, "`mesh DIR`: " + std::string("redo the stage even when it is unchanged since the last run"));
  sub->add_option("--organ", flags->organs,
                  "organ to mesh, NAME or NAME=LABEL (default: gallbladder=1 trachea=2); gallbladder gets a wall and "
                  "a body, trachea a tube wall around its lumen, other names one solid body");
  sub->add_option("--wall-mm", flags->wall_mm,
                  "wall thickness of an organ with a wall, ORGAN=MM, repeatable (default: the organ registry's:\n"
                  "gallbladder 2, trachea 2.5), e.g. --wall-mm gallbladder=3");
  sub->add_option("--max-fold-deg", flags->max_fold_deg,
                  "fold gate of an organ's uncut outer surface (gallbladder): largest angle between neighbouring triangles,\n"
                  "deg; a mesh failing it is remeshed smoother (default 60, or the run's [stages.mesh] max_fold_deg; 0 = off)")
      ->check(CLI::Range(0.0, 180.0));
  sub->add_flag("--no-tets", flags->no_tets, "surfaces only (no tetrahedral meshes)");
  sub->add_flag("--material-band", flags->material_band,
                "also write each organ's INP with the P5/P50/P95 variants of its materials, from the spread of\n"
                "their calibration (meshes/<organ>/band/<organ>.p05.inp, …; `simulate --band` runs them)");
  sub->add_flag("--allow-quality-failures", flags->allow_failures,
                "write the meshes even when a quality guarantee fails (quality.json says which)");
  return {Command{sub, [flags] { return run_mesh(*flags); }}};
}

}  // namespace organsmith
