#include "pipeline/output_scene.h"

#include "core/errors.h"
#include "pipeline/image_io.h"
#include "pipeline/ingest.h"
#include "viewer/label_surface.h"
#include "viewer/mesh_files.h"
#include "viewer/snapshot.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <fstream>
#include <map>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

/// Label values of the organs organsmith knows (see core/volume.h `Label`).
std::optional<std::uint8_t> organ_label(const std::string& name) {
  for (int v = 1; v <= 5; ++v)
    if (label_name(std::uint8_t(v)) == name) return std::uint8_t(v);
  return std::nullopt;
}

nlohmann::json read_json_or_null(const fs::path& p) {
  std::ifstream in(p);
  if (!in) return nullptr;
  try {
    return nlohmann::json::parse(in);
  } catch (const std::exception&) {
    spdlog::warn("{} is not valid JSON; ignored", p.string());
    return nullptr;
  }
}

/// Contours written by the segmentation stage (contours_<organ>.json). Read leniently: the file
/// is {"organ": …, "contours": [{"slice_k": k, "points_lps_mm": [[x, y, z], …], "closed": b}]}.
std::optional<ContourStack> read_contours(const fs::path& p, const std::string& organ) {
  const nlohmann::json j = read_json_or_null(p);
  if (!j.is_object() || !j.contains("contours") || !j["contours"].is_array()) return std::nullopt;
  ContourStack stack;
  stack.organ = j.value("organ", organ);
  try {
    for (const auto& c : j["contours"]) {
      Contour contour;
      contour.slice_k = c.value("slice_k", std::int64_t(0));
      contour.closed = c.value("closed", true);
      for (const auto& q : c.at("points_lps_mm")) contour.points_lps_mm.emplace_back(q.at(0), q.at(1), q.at(2));
      stack.contours.push_back(std::move(contour));
    }
  } catch (const std::exception&) {
    spdlog::warn("{}: contours not in the expected form; not drawn", p.string());
    return std::nullopt;
  }
  return stack;
}

}  // namespace

void load_output_scene(const fs::path& out, const LoadFlags& flags, OutputScene& os, Progress& progress) {
  std::error_code ec;
  if (!fs::is_directory(out, ec))
    throw InputError(ExitCode::input_not_found, "no such output directory", out,
                     "give the directory `organsmith run --out` wrote (default: out)");
  SnapshotScene& scene = os.scene;
  const nlohmann::json manifest = read_json_or_null(out / "manifest.json");
  scene.case_name = out.filename().string();
  if (manifest.is_object() && manifest.contains("case") && manifest["case"].is_object())
    scene.case_name = manifest["case"].value("name", scene.case_name);

  // Organs: those of the case, else the two organsmith models.
  std::vector<std::string> organ_names;
  if (manifest.is_object() && manifest.contains("case") && manifest["case"].contains("organs"))
    for (const auto& o : manifest["case"]["organs"])
      if (o.is_object() && o.contains("name")) organ_names.push_back(o["name"].get<std::string>());
  if (organ_names.empty()) organ_names = {"gallbladder", "trachea"};
  for (const auto& n : organ_names)
    if (const auto v = organ_label(n)) scene.organs.push_back({n, *v});

  // CT: as given, else the phantom the run synthesised, else the case's input.
  if (flags.need_ct) {
    fs::path ct = flags.ct;
    if (ct.empty() && fs::exists(out / "phantom" / "dicom")) ct = out / "phantom" / "dicom";
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

  // Labels: the segmentation, else the phantom's ground truth.
  fs::path labels = flags.labels;
  std::string source = "label map " + fs::path(flags.labels).filename().string();
  if (labels.empty() && fs::exists(out / "labels.nii.gz")) labels = out / "labels.nii.gz", source = "segmentation";
  if (labels.empty() && fs::exists(out / "phantom" / "ground_truth.nii.gz")) {
    labels = out / "phantom" / "ground_truth.nii.gz";
    source = "phantom ground truth";
    os.missing.push_back("the segmentation (labels.nii.gz): outlines show the phantom's ground truth instead");
  }
  if (!labels.empty()) {
    os.labels = read_label_map(labels);
    scene.labels = &*os.labels;
    scene.labels_source = source;
    if (os.ct && !os.labels->grid.same_geometry(os.ct->grid)) {
      spdlog::warn("{} is not on the CT's grid: slices are drawn without outlines", labels.string());
      scene.labels = nullptr;
    }
  } else {
    os.missing.push_back("a label map (labels.nii.gz or phantom/ground_truth.nii.gz): no outlines, no slice views");
  }

  // Contours of the segmentation stage.
  for (const auto& o : scene.organs)
    if (const auto p = out / ("contours_" + o.name + ".json"); fs::exists(p))
      if (auto stack = read_contours(p, o.name)) scene.contours.push_back(std::move(*stack));

  // Meshes (.vtp surfaces and paths, .vtu tetrahedra) anywhere in the output but the phantom
  // and the snapshots, in name order so that every run draws them in the same order.
  std::vector<fs::path> files;
  for (auto it = fs::recursive_directory_iterator(out, ec); !ec && it != fs::recursive_directory_iterator(); ++it) {
    const auto name = it->path().filename().string();
    if (it->is_directory() && (name == "phantom" || name == "snapshots" || name.rfind('.', 0) == 0)) {
      it.disable_recursion_pending();
      continue;
    }
    const auto ext = it->path().extension().string();
    if (it->is_regular_file() && (ext == ".vtp" || ext == ".vtu")) files.push_back(it->path());
  }
  std::sort(files.begin(), files.end());
  auto organ_of = [&](const std::string& stem) {
    for (const auto& o : scene.organs)
      if (stem.find(o.name) != std::string::npos) return o.name;
    return stem;
  };
  for (const auto& f : files) {
    MeshFileContents m;
    try {
      m = read_mesh_file(f);
    } catch (const Error& e) {
      spdlog::warn("{}", e.what());
      continue;
    }
    const std::string stem = f.stem().string(), organ = organ_of(stem);
    if (!m.surface.triangles.empty()) {
      SceneSurface s;
      s.name = stem;
      s.organ = organ;
      s.colour = organ_colour(organ);
      s.mesh = std::move(m.surface);
      s.source = "mesh stage";
      scene.surfaces.push_back(std::move(s));
    }
    for (auto& l : m.lines) scene.paths.push_back({std::move(l)});
    if (!m.tets.tets.empty()) scene.tet_meshes.push_back({organ, std::move(m.tets)});
  }
  // An organ drawn with several surfaces: the outermost (largest volume) is its wall, translucent.
  std::map<std::string, std::vector<SceneSurface*>> by_organ;
  for (auto& s : scene.surfaces) by_organ[s.organ].push_back(&s);
  for (auto& [organ, list] : by_organ)
    if (list.size() > 1) {
      auto outer = std::max_element(list.begin(), list.end(), [](auto* a, auto* b) {
        return std::abs(a->mesh.signed_volume_mm3()) < std::abs(b->mesh.signed_volume_mm3());
      });
      (*outer)->opacity = 0.35;
    }

  // Organs the meshing stage has not (yet) produced: a label-map isosurface, said so in the title.
  if (scene.labels) {
    for (const auto& o : scene.organs) {
      if (by_organ.count(o.name)) continue;
      SceneSurface s;
      s.name = o.name;
      s.organ = o.name;
      s.colour = organ_colour(o.name);
      s.mesh = label_surface(*scene.labels, o.label);
      s.source = "label-map isosurface (no mesh-stage output)";
      if (s.mesh.triangles.empty()) {
        os.missing.push_back("organ " + o.name + " (absent from the label map)");
        continue;
      }
      os.missing.push_back("the " + o.name + " mesh (meshing stage output): drawn as a label-map isosurface");
      scene.surfaces.push_back(std::move(s));
    }
    // Context for the overview: the liver around the gallbladder, the lungs around the trachea,
    // from the label map when it has them, else from the phantom's ground truth.
    const LabelMap* context_labels = scene.labels;
    std::optional<LabelMap> truth;
    if (flags.context_step_vox > 0 && scene.labels->count(3) == 0 && scene.labels->count(4) == 0 &&
        fs::exists(out / "phantom" / "ground_truth.nii.gz")) {
      truth = read_label_map(out / "phantom" / "ground_truth.nii.gz");
      context_labels = &*truth;
    }
    for (const char* name : {"liver", "lungs"}) {
      const auto v = organ_label(name);
      if (!v || flags.context_step_vox <= 0) continue;
      SceneSurface s;
      s.name = name;
      s.organ = name;
      s.colour = organ_colour(name);
      s.opacity = std::string(name) == "liver" ? 0.3 : 0.15;
      s.context = true;
      LabelSurfaceOptions lo;
      lo.step_vox = flags.context_step_vox;
      s.mesh = label_surface(*context_labels, *v, lo);
      s.source = truth ? "context from phantom ground truth" : "";
      if (!s.mesh.triangles.empty()) scene.surfaces.push_back(std::move(s));
    }
  }
  if (scene.tet_meshes.empty()) os.missing.push_back("tetrahedral meshes (.vtu): no tets_ views");
  if (scene.paths.empty()) os.missing.push_back("guidance paths: the overview has none");
  os.missing.push_back("calibration plots: `organsmith calibrate` results are not drawn by this command yet");
}

}  // namespace organsmith
