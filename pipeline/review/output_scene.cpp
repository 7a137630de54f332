#include "pipeline/review/output_scene.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "physics/haptics/paths.h"
#include "physics/materials/presets.h"
#include "physics/materials/uncertainty.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/ingest.h"
#include "pipeline/case/organ_registry.h"
#include "pipeline/output/json_file.h"
#include "pipeline/output/output_layout.h"
#include "pipeline/output/read_manifest.h"
#include "pipeline/review/output_plots.h"
#include "segmentation/segment.h"
#include "viewer/label_surface.h"
#include "viewer/mesh_files.h"
#include "viewer/snapshot.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {


/// Contours written by the segmentation stage (contours_<organ>.json), through their reader;
/// read leniently: a file not in that form is not drawn.
std::optional<ContourStack> read_contours(const fs::path& p, const std::string& organ) {
  const std::optional<std::string> text = read_file(p);
  if (!text) return std::nullopt;
  std::string why;
  std::optional<ContourStack> stack = contours_from_json(*text, organ, &why);
  if (!stack && !why.empty()) spdlog::warn("{}: {}; not drawn", p.string(), why);
  return stack;
}

/// Display colour of a guidance path by name: distinct from the organs it lies on.
Rgb path_colour(const std::string& name) {
  if (name.find("centerline") != std::string::npos || name.find("centreline") != std::string::npos)
    return {0.25, 0.45, 1.0};  // blue, not the cyan of the preview's tool
  if (name.find("incision") != std::string::npos) return {1.0, 0.85, 0.10};
  if (name.find("dissection") != std::string::npos) return {0.95, 0.30, 0.85};
  return {1.0, 0.60, 0.15};
}

}  // namespace

void load_output_scene(const fs::path& out, const LoadFlags& flags, OutputScene& os, Progress& progress) {
  std::error_code ec;
  if (!fs::is_directory(out, ec))
    throw InputError(ExitCode::input_not_found, "no such output directory", out,
                     "give the directory `organsmith run --out` wrote (default: out)");
  SnapshotScene& scene = os.scene;
  const nlohmann::json manifest = read_manifest(out).value_or(nlohmann::json());
  scene.case_name = flags.case_name.empty() ? out.filename().string() : flags.case_name;
  if (flags.case_name.empty() && manifest.is_object() && manifest.contains("case") && manifest["case"].is_object())
    scene.case_name = manifest["case"].value("name", scene.case_name);

  // Organs: those of the case, else every organ of the registry with a model.
  const OrganRegistry registry = flags.registry ? *flags.registry : registry_of_output(out);
  std::vector<std::string> organ_names = flags.organs;
  if (organ_names.empty() && manifest.is_object() && manifest.contains("case") && manifest["case"].contains("organs"))
    for (const auto& o : manifest["case"]["organs"])
      if (o.is_object() && o.contains("name")) organ_names.push_back(o["name"].get<std::string>());
  if (organ_names.empty()) organ_names = registry.modelled();
  auto rgb = [](const OrganInfo& o) { return Rgb{o.colour_rgb[0], o.colour_rgb[1], o.colour_rgb[2]}; };
  for (const auto& n : organ_names)
    if (const OrganInfo* o = registry.find(n)) scene.organs.push_back({n, o->label, rgb(*o)});

  // CT: this run's, else as given, else the phantom the run synthesised, else the case's input.
  const OutputLayout layout{out};
  if (flags.need_ct && flags.ct_volume) {
    scene.ct = flags.ct_volume;
  } else if (flags.need_ct) {
    fs::path ct = flags.ct;
    if (ct.empty() && fs::exists(layout.phantom_dicom())) ct = layout.phantom_dicom();
    if (ct.empty() && manifest.is_object() && manifest.contains("case") && manifest["case"].contains("input")) {
      const auto& in = manifest["case"]["input"];
      if (in.is_string() && fs::exists(in.get<std::string>())) ct = in.get<std::string>();
    }
    if (ct.empty()) {
      os.missing.push_back("the CT (no phantom/dicom in the output, no readable case input; give --ct): no slice views");
    } else {
      IngestResult r = ingest(ct, IngestOptions{}, progress);
      os.ct = std::move(r.volume);
      scene.ct = &*os.ct;
    }
  }

  // Labels: this run's segmentation, else as given, else the file, else the phantom's ground truth.
  fs::path labels = flags.labels;
  std::string source = "label map " + fs::path(flags.labels).filename().string();
  if (labels.empty() && (flags.label_map || fs::exists(layout.labels()))) labels = layout.labels(), source = "segmentation";
  if (labels.empty() && (flags.phantom_truth || fs::exists(layout.phantom_truth()))) {
    labels = layout.phantom_truth();
    source = "phantom ground truth";
    os.missing.push_back("the segmentation (labels.nii.gz): outlines show the phantom's ground truth instead");
  }
  if (!labels.empty()) {
    const LabelMap* lm = nullptr;
    if (flags.label_map && flags.labels.empty()) {
      lm = flags.label_map;
    } else if (flags.phantom_truth && labels == layout.phantom_truth()) {
      lm = flags.phantom_truth;
    } else {
      os.labels = read_label_map(labels);
      lm = &*os.labels;
    }
    scene.labels = lm;
    scene.labels_source = source;
    if (scene.ct && !lm->grid.same_geometry(scene.ct->grid)) {
      spdlog::warn("{} is not on the CT's grid: slices are drawn without outlines", labels.string());
      scene.labels = nullptr;
    }
  } else {
    os.missing.push_back("a label map (labels.nii.gz or phantom/ground_truth.nii.gz): no outlines, no slice views");
  }

  // Contours of the segmentation stage.
  for (const auto& o : scene.organs) {
    if (flags.contours) {
      for (const ContourStack& c : *flags.contours)
        if (c.organ == o.name) scene.contours.push_back(c);
    } else if (const auto p = layout.contours(o.name); fs::exists(p)) {
      if (auto stack = read_contours(p, o.name)) scene.contours.push_back(std::move(*stack));
    }
  }

  // Meshes of the mesh stage: meshes/<organ>/<surface>.vtp and meshes/<organ>/<organ>.vtu, by the
  // surfaces the registry says the organ's model has; drawn in path order, as every run does.
  struct MeshFile {
    fs::path path;
    const OrganInfo* organ;
    bool surface;
  };
  std::vector<MeshFile> files;
  std::map<std::string, std::vector<SceneSurface*>> by_organ;
  if (flags.meshes) {
    // This run's meshes, in the order the files would be read (by path): organs in name order,
    // then the organ's surfaces by name, then its tets.
    std::vector<std::pair<fs::path, std::function<void()>>> items;
    for (const auto& so : scene.organs) {
      const OrganInfo& info = registry.at(so.name);
      for (const OrganMesh& om : flags.meshes->organs) {
        if (om.spec.name != so.name) continue;
        for (const NamedSurface& ns : om.surfaces) {
          const auto& names = info.surfaces();
          if (std::find(names.begin(), names.end(), ns.name) == names.end() || ns.mesh.triangles.empty()) continue;
          items.push_back({layout.surface(so.name, ns.name, "vtp"), [&scene, &ns, &info, rgb] {
                             SceneSurface s;
                             s.name = ns.name;
                             s.organ = info.name;
                             s.colour = rgb(info);
                             s.mesh = ns.mesh;
                             s.source = "mesh stage";
                             scene.surfaces.push_back(std::move(s));
                           }});
        }
        if (!om.volume.tets.empty())
          items.push_back({layout.volume(so.name, "vtu"), [&scene, &om] { scene.tet_meshes.push_back({om.spec.name, om.volume}); }});
      }
    }
    std::stable_sort(items.begin(), items.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (auto& [_, add] : items) add();
  } else {
    for (const auto& so : scene.organs) {
      const OrganInfo& info = registry.at(so.name);
      for (const auto& surface : info.surfaces())
        if (const fs::path f = layout.surface(so.name, surface, "vtp"); fs::is_regular_file(f, ec))
          files.push_back({f, &info, true});
      if (const fs::path f = layout.volume(so.name, "vtu"); fs::is_regular_file(f, ec)) files.push_back({f, &info, false});
    }
  }
  std::sort(files.begin(), files.end(), [](const MeshFile& a, const MeshFile& b) { return a.path < b.path; });
  for (const auto& f : files) {
    MeshFileContents m;
    try {
      m = read_mesh_file(f.path);
    } catch (const Error& e) {
      spdlog::warn("{}", e.what());
      continue;
    }
    if (f.surface && !m.surface.triangles.empty()) {
      SceneSurface s;
      s.name = f.path.stem().string();
      s.organ = f.organ->name;
      s.colour = rgb(*f.organ);
      s.mesh = std::move(m.surface);
      s.source = "mesh stage";
      scene.surfaces.push_back(std::move(s));
    }
    if (!f.surface && !m.tets.tets.empty()) scene.tet_meshes.push_back({f.organ->name, std::move(m.tets)});
  }
  // An organ drawn with several surfaces: its wall (the registry says which) is translucent.
  for (auto& s : scene.surfaces) by_organ[s.organ].push_back(&s);
  for (auto& [organ, list] : by_organ) {
    const OrganInfo& info = registry.at(organ);
    for (auto* s : list)
      if (list.size() > 1 && s->name == info.wall_surface()) s->opacity = 0.35;
  }

  // Organs the meshing stage has not (yet) produced: a label-map isosurface, said so in the title.
  if (scene.labels) {
    for (const auto& o : scene.organs) {
      if (by_organ.count(o.name)) continue;
      SceneSurface s;
      s.name = o.name;
      s.organ = o.name;
      s.colour = o.colour;
      s.mesh = label_surface(*scene.labels, o.label);
      s.source = "label-map isosurface (no mesh-stage output)";
      if (s.mesh.triangles.empty()) {
        os.missing.push_back("organ " + o.name + " (absent from the label map)");
        continue;
      }
      os.missing.push_back("the " + o.name + " mesh (meshing stage output): drawn as a label-map isosurface");
      scene.surfaces.push_back(std::move(s));
    }
    // Context for the overview: the registry's context organs (the liver around the gallbladder,
    // the lungs around the trachea), from the label map when it has any, else from the phantom's
    // ground truth.
    std::vector<const OrganInfo*> context;
    for (const auto& o : registry.organs)
      if (o.mesh == OrganMeshModel::none && o.opacity > 0 &&
          std::find(organ_names.begin(), organ_names.end(), o.name) == organ_names.end())
        context.push_back(&o);
    const LabelMap* context_labels = scene.labels;
    std::optional<LabelMap> truth;
    const bool labels_have_context =
        std::any_of(context.begin(), context.end(), [&](const OrganInfo* o) { return scene.labels->count(o->label) > 0; });
    bool from_truth = false;
    if (flags.context_step_vox > 0 && !labels_have_context && flags.phantom_truth) {
      context_labels = flags.phantom_truth;
      from_truth = true;
    } else if (flags.context_step_vox > 0 && !labels_have_context && fs::exists(layout.phantom_truth())) {
      truth = read_label_map(layout.phantom_truth());
      context_labels = &*truth;
      from_truth = true;
    }
    for (const OrganInfo* o : context) {
      if (flags.context_step_vox <= 0) break;
      SceneSurface s;
      s.name = o->name;
      s.organ = o->name;
      s.colour = rgb(*o);
      s.opacity = o->opacity;
      s.context = true;
      LabelSurfaceOptions lo;
      lo.step_vox = flags.context_step_vox;
      s.mesh = label_surface(*context_labels, o->label, lo);
      s.source = from_truth ? "context from phantom ground truth" : "";
      if (!s.mesh.triangles.empty()) scene.surfaces.push_back(std::move(s));
    }
  }
  if (scene.tet_meshes.empty()) os.missing.push_back("tetrahedral meshes (.vtu): no tets_ views");

  // Guidance paths of the guide stage (OUT/paths/<name>.json), in file-name order.
  if (flags.paths) {
    std::vector<const Polyline*> sorted;
    for (const Polyline& p : *flags.paths) sorted.push_back(&p);
    std::stable_sort(sorted.begin(), sorted.end(),
                     [](const Polyline* a, const Polyline* b) { return a->name + ".json" < b->name + ".json"; });
    for (const Polyline* line : sorted) scene.paths.push_back({*line, path_colour(line->name)});
  } else {
    std::vector<fs::path> path_files;
    for (auto it = fs::directory_iterator(layout.paths_dir(), ec); !ec && it != fs::directory_iterator(); ++it)
      if (it->is_regular_file() && it->path().extension() == ".json") path_files.push_back(it->path());
    ec.clear();
    std::sort(path_files.begin(), path_files.end());
    for (const auto& f : path_files) {
      try {
        ScenePath p;
        p.line = physics::read_path_file(f);
        p.line.name = f.stem().string();
        p.colour = path_colour(p.line.name);
        scene.paths.push_back(std::move(p));
      } catch (const Error& e) {
        spdlog::warn("{}", e.what());
      }
    }
  }
  if (scene.paths.empty()) os.missing.push_back("guidance paths (paths/*.json, the guide stage): the overview has none");

  // Plots: the materials of the attach stage; calibrate / uncertainty results under OUT or named.
  if (flags.plots) {
    std::optional<MaterialsFile> read;
    if (!flags.materials) {
      try {
        read = read_materials(out);
      } catch (const Error& e) {
        spdlog::warn("{}", e.what());
      }
    }
    if (const MaterialsFile* m = flags.materials ? flags.materials : read ? &*read : nullptr)
      for (auto& p : material_plots(*m, registry)) scene.plots.push_back(std::move(p));
    std::vector<fs::path> dirs;
    for (const auto& d : flags.calibration_dirs) {
      if (!fs::is_directory(d, ec))
        throw InputError(ExitCode::input_not_found, "no such calibration directory", d,
                         "give the --out directory of `organsmith calibrate` or `organsmith uncertainty`");
      dirs.push_back(d);
    }
    for (auto it = fs::recursive_directory_iterator(out, ec); !ec && it != fs::recursive_directory_iterator(); ++it) {
      const auto name = it->path().filename().string();
      if (it->is_directory() && (name == "phantom" || name == "snapshots" || name == "meshes" || name == "overlays" ||
                                 name.rfind('.', 0) == 0)) {
        it.disable_recursion_pending();
        continue;
      }
      if (it->is_directory()) dirs.push_back(it->path());
    }
    ec.clear();
    std::sort(dirs.begin() + std::ptrdiff_t(flags.calibration_dirs.size()), dirs.end());
    std::set<std::string> used;
    auto stem_of = [&](const fs::path& d) {
      std::string stem;
      for (const char c : d.filename().string()) stem += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
      if (stem.empty()) stem = "results";
      std::string unique = stem;
      for (int k = 2; used.count(unique); ++k) unique = stem + "_" + std::to_string(k);
      used.insert(unique);
      return unique;
    };
    for (const auto& d : dirs) {
      const bool fit = fs::exists(CalibrateLayout{d}.params()) && fs::exists(CalibrateLayout{d}.fit());
      const bool mc = fs::exists(UncertaintyLayout{d}.mc_summary()) && fs::exists(UncertaintyLayout{d}.mc_cdf());
      if (!fit && !mc) continue;
      const std::string stem = stem_of(d);
      if (fit)
        if (auto p = calibration_fit_plot(d, stem)) scene.plots.push_back(std::move(*p));
      if (mc)
        if (auto p = monte_carlo_plot(d, stem)) scene.plots.push_back(std::move(*p));
    }
    if (scene.plots.empty())
      os.missing.push_back("materials.json and calibration results (params.json + fit.csv, summary.json + cdf.csv): no plots");
  }
}

}  // namespace organsmith
