#include "pipeline/output_scene.h"

#include "core/errors.h"
#include "physics/haptics/paths.h"
#include "physics/materials/presets.h"
#include "physics/materials/uncertainty.h"
#include "pipeline/image_io.h"
#include "pipeline/ingest.h"
#include "pipeline/organ_registry.h"
#include "pipeline/output_layout.h"
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

/// Display colour of a guidance path by name: distinct from the organs it lies on.
Rgb path_colour(const std::string& name) {
  if (name.find("centerline") != std::string::npos || name.find("centreline") != std::string::npos)
    return {0.25, 0.45, 1.0};  // blue, not the cyan of the preview's tool
  if (name.find("incision") != std::string::npos) return {1.0, 0.85, 0.10};
  if (name.find("dissection") != std::string::npos) return {0.95, 0.30, 0.85};
  return {1.0, 0.60, 0.15};
}

/// A CSV with a header row, as columns by name (numbers; text columns kept as text).
struct Csv {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  int column(const std::string& name) const {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return int(i);
    return -1;
  }
};

std::optional<Csv> read_csv(const fs::path& p) {
  std::ifstream in(p);
  if (!in) return std::nullopt;
  Csv csv;
  std::string line;
  auto split = [](const std::string& l) {
    std::vector<std::string> out;
    std::stringstream ss(l);
    std::string cell;
    while (std::getline(ss, cell, ',')) {
      while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
      out.push_back(cell);
    }
    return out;
  };
  if (!std::getline(in, line)) return std::nullopt;
  csv.header = split(line);
  while (std::getline(in, line))
    if (!line.empty()) csv.rows.push_back(split(line));
  return csv;
}

double number(const std::vector<std::string>& row, int col) {
  if (col < 0 || std::size_t(col) >= row.size()) return std::nan("");
  try {
    return std::stod(row[col]);
  } catch (const std::exception&) {
    return std::nan("");
  }
}

// Series colours for several curves on one chart (colour-blind friendly order).
const Rgb kSeriesColours[] = {{0.00, 0.45, 0.70}, {0.84, 0.37, 0.00}, {0.00, 0.62, 0.45}, {0.80, 0.47, 0.65},
                              {0.34, 0.71, 0.91}, {0.90, 0.62, 0.00}, {0.35, 0.35, 0.35}};
Rgb series_colour(std::size_t i) { return kSeriesColours[i % std::size(kSeriesColours)]; }

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

/// `organsmith calibrate` output (params.json + fit.csv): measured points against the fitted
/// model, one pair of series per specimen and load case.
std::optional<Plot> calibration_fit_plot(const fs::path& dir, const std::string& stem) {
  const nlohmann::json params = read_json_or_null(dir / "params.json");
  const auto csv = read_csv(dir / "fit.csv");
  if (!params.is_object() || !csv) return std::nullopt;
  const bool cutting = csv->column("displacement_m") >= 0;
  const int cx = csv->column(cutting ? "displacement_m" : "stretch");
  const int cm = csv->column(cutting ? "force_n" : "stress_pa");
  const int cf = csv->column(cutting ? "model_force_n" : "model_stress_pa");
  const int cs = csv->column("specimen"), cl = csv->column("load");
  if (cx < 0 || cm < 0 || cf < 0) {
    spdlog::warn("{}: columns not as `organsmith calibrate` writes them; not drawn", (dir / "fit.csv").string());
    return std::nullopt;
  }
  // Measured points by (load, specimen): colour by load case, marker by specimen. The fitted
  // model by load case (one model for every specimen), at the measured abscissae.
  std::vector<std::string> loads, specimens;
  std::map<std::pair<std::string, std::string>, PlotSeries> measured;
  std::map<std::string, std::map<double, std::pair<double, int>>> fitted;  // load → x → (sum, n)
  auto index_of = [](std::vector<std::string>& v, const std::string& k) {
    const auto it = std::find(v.begin(), v.end(), k);
    if (it != v.end()) return std::size_t(it - v.begin());
    v.push_back(k);
    return v.size() - 1;
  };
  for (const auto& row : csv->rows) {
    const std::string spec = cs >= 0 && std::size_t(cs) < row.size() ? row[cs] : "";
    std::string load = cl >= 0 && std::size_t(cl) < row.size() ? row[cl] : "";
    if (load.rfind("uniaxial-", 0) == 0) load = load.substr(9);
    const double x0 = number(row, cx), m = number(row, cm), f = number(row, cf);
    if (!std::isfinite(x0) || !std::isfinite(m) || !std::isfinite(f)) continue;
    // Cutting: displacement in mm and force in N read better; stress in kPa.
    const double x = cutting ? x0 * 1e3 : x0, scale = cutting ? 1.0 : 1e-3;
    const std::size_t li = index_of(loads, load), si = index_of(specimens, spec);
    PlotSeries& ms = measured[{load, spec}];
    if (ms.x.empty()) {
      ms.name = (load.empty() ? std::string("measured") : load) + (spec.empty() ? "" : " (" + spec + ")");
      ms.points = true;
      ms.colour = series_colour(li);
      ms.marker = int(si % 5);
    }
    ms.x.push_back(x), ms.y.push_back(m * scale);
    auto& acc = fitted[load][x];
    acc.first += f * scale, acc.second += 1;
  }
  if (measured.empty()) return std::nullopt;
  Plot p;
  p.name = "fit_" + stem;
  const std::string model = params.value("model", std::string("model"));
  p.title = "Calibration: measured vs fitted " + model;
  p.x_label = cutting ? "blade displacement (mm)" : "stretch";
  p.y_label = cutting ? "force (N)" : "nominal stress (kPa)";
  std::string note = fs::path(params.value("data", std::string("?"))).filename().string() + "  |  " +
                     std::to_string(params.value("points", 0)) + " points";
  if (params.contains("r2") && params["r2"].is_number()) note += "  |  R² " + fmt("%.4f", params["r2"].get<double>());
  if (params.contains("rmse") && params["rmse"].is_number())
    note += ", RMSE " + fmt("%.4g", params["rmse"].get<double>()) + (cutting ? " N" : " Pa");
  p.note = note + "  |  " + dir.filename().string();
  std::size_t shown = 0;
  for (const auto& load : loads) {
    for (const auto& spec : specimens)
      if (auto it = measured.find({load, spec}); it != measured.end() && shown < 12) {
        p.series.push_back(std::move(it->second));
        ++shown;
      }
    PlotSeries line;
    line.name = (load.empty() ? std::string("") : load + " ") + "fitted";
    line.colour = series_colour(std::size_t(std::find(loads.begin(), loads.end(), load) - loads.begin()));
    for (const auto& [x, acc] : fitted[load]) line.x.push_back(x), line.y.push_back(acc.first / acc.second);
    p.series.push_back(std::move(line));
  }
  if (measured.size() > 12) p.note += "  |  first 12 of " + std::to_string(measured.size()) + " measured curves";
  return p;
}

/// `organsmith uncertainty --method mc` output (cdf.csv + summary.json): the stress CDF at each
/// stretch.
std::optional<Plot> monte_carlo_plot(const fs::path& dir, const std::string& stem) {
  const nlohmann::json summary = read_json_or_null(dir / "summary.json");
  const auto csv = read_csv(dir / "cdf.csv");
  if (!summary.is_object() || !csv) return std::nullopt;
  const int cs = csv->column("stretch"), cp = csv->column("probability"), cx = csv->column("stress_pa");
  if (cs < 0 || cp < 0 || cx < 0) return std::nullopt;
  std::vector<double> order;
  std::map<double, PlotSeries> by_stretch;
  for (const auto& row : csv->rows) {
    const double s = number(row, cs), p = number(row, cp), x = number(row, cx);
    if (!std::isfinite(s) || !std::isfinite(p) || !std::isfinite(x)) continue;
    if (!by_stretch.count(s)) order.push_back(s);
    by_stretch[s].x.push_back(x / 1e3);
    by_stretch[s].y.push_back(p);
  }
  if (order.empty()) return std::nullopt;
  Plot p;
  p.name = "cdf_" + stem;
  p.title = "Monte Carlo CDFs of the stress at each stretch";
  p.x_label = "nominal stress (kPa)";
  p.y_label = "probability";
  p.note = summary.value("preset", std::string("?")) + "  |  " + std::to_string(summary.value("samples", 0)) +
           " draws, spread " + summary.value("spread", std::string("?")) + "  |  " + dir.filename().string();
  // Stresses spanning more than ~1.5 decades: a logarithmic axis, else the low curves are lost.
  double lo = 1e300, hi = 0;
  for (const auto& [_, ser] : by_stretch)
    for (const double v : ser.x)
      if (v > 0) lo = std::min(lo, v), hi = std::max(hi, v);
  if (hi > 30 * lo) {
    p.log_x = true;
    p.x_label = "nominal stress (Pa, logarithmic)";
    for (auto& [_, ser] : by_stretch)
      for (double& v : ser.x) v *= 1e3;
  }
  for (std::size_t i = 0; i < order.size(); ++i) {
    PlotSeries s = std::move(by_stretch[order[i]]);
    s.name = "stretch " + fmt("%.3g", order[i]);
    s.colour = series_colour(i);
    p.series.push_back(std::move(s));
  }
  return p;
}

/// The laws of the organ regions in materials.json (the attach stage), uniaxial, with the
/// 5–95 % band of a Monte Carlo over the preset's standard deviations where the thesis gives
/// them; and the CDFs of that Monte Carlo at a few stretches.
std::vector<Plot> material_plots(const fs::path& out, const OrganRegistry& registry) {
  std::vector<Plot> plots;
  const nlohmann::json mj = read_json_or_null(OutputLayout{out}.materials());
  if (!mj.is_object() || !mj.contains("regions") || !mj["regions"].is_object()) return plots;
  const physics::MaterialLibrary lib = physics::builtin_material_library();
  Plot laws;
  laws.name = "materials";
  laws.title = "Calibrated tissue laws of the organ regions";
  laws.x_label = "stretch (uniaxial)";
  laws.y_label = "nominal stress (Pa, logarithmic)";
  laws.log_y = true;
  laws.note = "materials.json (attach stage); dashed: 5 % and 95 % of 2000 Monte Carlo draws over the thesis' sd";
  Plot cdf;
  constexpr double kMaxStretch = 1.6;  // the calibrated range (physics/haptics/HAPTICS.md: ε ≤ 0.6)
  std::vector<physics::LoadPoint> pts;
  // Stretch 1.01, 1.02, …, 1.60; the unloaded state (zero stress) has no place on the chart's
  // logarithmic axis.
  for (int i = 1; i <= 60; ++i)
    pts.push_back({1.0 + (kMaxStretch - 1.0) * i / 60.0, 1.0, physics::LoadCase::uniaxial_circumferential});
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  // Regions with identical laws share one curve.
  std::vector<std::pair<std::vector<std::string>, RegionLaw>> distinct;
  for (const auto& [region, _] : mj["regions"].items()) {
    RegionLaw law;
    try {
      law = region_law(out, region, registry);
    } catch (const Error& e) {
      spdlog::warn("{}", e.what());
      continue;
    }
    bool merged = false;
    for (auto& [names, l] : distinct)
      if (l.material.model == law.material.model && l.material.parameters.size() == law.material.parameters.size() &&
          std::equal(l.material.parameters.begin(), l.material.parameters.end(), law.material.parameters.begin(),
                     [](const auto& a, const auto& b) { return a.name == b.name && a.value == b.value; })) {
        names.push_back(region);
        merged = true;
      }
    if (!merged) distinct.push_back({{region}, law});
  }
  std::size_t colour = 0;
  for (const auto& [names, law] : distinct) {
    std::unique_ptr<physics::Model> model;
    std::vector<double> mean;
    try {
      model = physics::make_model(law.material.model, law.options);
      mean = physics::parameter_values(*model, law.material.parameters);
    } catch (const Error& e) {
      spdlog::warn("materials plot: {}: {}", names.front(), e.what());
      continue;
    }
    if (model->name() == "kelvin-cutting") continue;  // not a stress–stretch law
    std::vector<double> stress(pts.size());
    model->respond(pts, mean, stress);
    std::string label;
    for (const auto& n : names) label += (label.empty() ? "" : " = ") + n;
    PlotSeries line;
    line.name = label + " (" + std::string(model->name()) + ")";
    line.colour = series_colour(colour++);
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (positive(stress[i])) line.x.push_back(pts[i].x), line.y.push_back(stress[i]);
    if (line.x.empty()) continue;
    laws.series.push_back(line);
    // The band, where the preset carries standard deviations.
    const physics::MaterialPreset* preset = nullptr;
    for (const auto& m : lib.materials)
      if (m.id == law.preset_id) preset = &m;
    if (!preset) continue;
    const char* spread_kind = preset->spreads.count("sd") ? "sd" : preset->spreads.count("dc_sd") ? "dc_sd" : nullptr;
    if (!spread_kind) continue;
    std::vector<double> sd;
    try {
      sd = physics::parameter_values(*model, preset->spreads.at(spread_kind));
    } catch (const Error&) {
      continue;
    }
    physics::MonteCarloOptions mo;
    mo.samples = 2000;
    mo.seed = 1;
    const physics::MonteCarloResult mc = physics::monte_carlo(*model, pts, mean, sd, mo);
    if (mc.stress_Pa.rows() < 10) continue;
    PlotSeries lo, hi;
    lo.name = label + ": 5-95 % band", hi.name = label + " 95 %";
    hi.in_legend = false;
    lo.colour = hi.colour = line.colour;
    lo.dashed = hi.dashed = true;
    const double levels[2] = {0.05, 0.95};
    for (std::size_t k = 0; k < pts.size(); ++k) {
      const auto q = physics::stress_quantiles(mc, int(k), levels);
      if (positive(q[0])) lo.x.push_back(pts[k].x), lo.y.push_back(q[0]);
      if (positive(q[1])) hi.x.push_back(pts[k].x), hi.y.push_back(q[1]);
    }
    laws.series.push_back(lo);
    laws.series.push_back(hi);
    if (cdf.series.empty()) {
      cdf.name = "mc_" + names.front();
      cdf.title = "Monte Carlo CDFs of the " + names.front() + " stress";
      cdf.x_label = "nominal stress (Pa, logarithmic)";
      cdf.y_label = "probability";
      cdf.log_x = true;
      cdf.note = law.preset_id + ", " + std::to_string(mc.stress_Pa.rows()) + " valid draws of mean ± " + spread_kind +
                 " (independent normal parameters, seed 1)";
      std::vector<double> levels_all;
      for (int i = 0; i <= 100; ++i) levels_all.push_back(i / 100.0);
      std::size_t c = 0;
      for (const double s : {1.1, 1.2, 1.3, 1.4, 1.5}) {
        const int k = int(std::lround((s - 1.0) / (kMaxStretch - 1.0) * 60.0)) - 1;
        const auto q = physics::stress_quantiles(mc, k, levels_all);
        PlotSeries ser;
        ser.name = "stretch " + fmt("%.2f", pts[k].x);
        ser.colour = series_colour(c++);
        ser.x.resize(q.size());
        std::copy(q.begin(), q.end(), ser.x.begin());
        ser.y = levels_all;
        cdf.series.push_back(std::move(ser));
      }
    }
  }
  if (!laws.series.empty()) plots.push_back(std::move(laws));
  if (!cdf.series.empty()) plots.push_back(std::move(cdf));
  return plots;
}

}  // namespace

RegionLaw region_law(const fs::path& out, const std::string& region, const OrganRegistry& registry) {
  RegionLaw law;
  const fs::path mf = OutputLayout{out}.materials();
  if (fs::exists(mf)) {
    std::ifstream in(mf);
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
      throw InputError(ExitCode::unsupported_input, std::string("materials.json is not valid JSON: ") + e.what(), mf,
                       "rerun the attach stage (`organsmith run --force`)");
    }
    if (j.contains("regions") && j["regions"].is_object() && j["regions"].contains(region)) {
      const auto& r = j["regions"][region];
      try {
        law.material.model = r.at("model").get<std::string>();
        for (const auto& p : r.at("parameters"))
          law.material.parameters.push_back({p.at("name").get<std::string>(), p.at("value").get<double>(), p.value("unit", "")});
        if (r.contains("constants") && r["constants"].contains("bulk_modulus_Pa"))
          law.options.bulk_modulus_Pa = r["constants"]["bulk_modulus_Pa"].get<double>();
        law.preset_id = r.value("preset", std::string());
        law.material.source = r.value("source", std::string());
      } catch (const nlohmann::json::exception& e) {
        throw InputError(ExitCode::unsupported_input, "region " + region + " of materials.json is malformed: " + e.what(),
                         mf, "rerun the attach stage (`organsmith run --force`)");
      }
      law.from_output = true;
      return law;
    }
  }
  const physics::MaterialLibrary lib = physics::builtin_material_library();
  std::string preset_id;
  for (const auto& o : registry.organs)
    if (const auto it = o.materials.find(region); it != o.materials.end()) preset_id = it->second;
  if (preset_id.empty())
    throw InputError(ExitCode::unsupported_input, "no material for region " + region, mf,
                     "run the attach stage, or see `organsmith materials` for the regions");
  const physics::MaterialPreset& preset = lib.find(preset_id);
  law.material = preset.material;
  law.options = physics::model_options_for(preset);
  law.preset_id = preset.id;
  return law;
}

void load_output_scene(const fs::path& out, const LoadFlags& flags, OutputScene& os, Progress& progress) {
  std::error_code ec;
  if (!fs::is_directory(out, ec))
    throw InputError(ExitCode::input_not_found, "no such output directory", out,
                     "give the directory `organsmith run --out` wrote (default: out)");
  SnapshotScene& scene = os.scene;
  const nlohmann::json manifest = read_json_or_null(OutputLayout{out}.manifest());
  scene.case_name = out.filename().string();
  if (manifest.is_object() && manifest.contains("case") && manifest["case"].is_object())
    scene.case_name = manifest["case"].value("name", scene.case_name);

  // Organs: those of the case, else every organ of the registry with a model.
  const OrganRegistry registry = flags.registry ? *flags.registry : registry_of_output(out);
  std::vector<std::string> organ_names;
  if (manifest.is_object() && manifest.contains("case") && manifest["case"].contains("organs"))
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
  if (labels.empty() && fs::exists(layout.phantom_truth())) {
    labels = layout.phantom_truth();
    source = "phantom ground truth";
    os.missing.push_back("the segmentation (labels.nii.gz): outlines show the phantom's ground truth instead");
  }
  if (!labels.empty()) {
    const LabelMap* lm = nullptr;
    if (flags.label_map && flags.labels.empty()) {
      lm = flags.label_map;
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
  for (const auto& o : scene.organs)
    if (const auto p = layout.contours(o.name); fs::exists(p))
      if (auto stack = read_contours(p, o.name)) scene.contours.push_back(std::move(*stack));

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
    if (flags.context_step_vox > 0 && !labels_have_context && fs::exists(layout.phantom_truth())) {
      truth = read_label_map(layout.phantom_truth());
      context_labels = &*truth;
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
      s.source = truth ? "context from phantom ground truth" : "";
      if (!s.mesh.triangles.empty()) scene.surfaces.push_back(std::move(s));
    }
  }
  if (scene.tet_meshes.empty()) os.missing.push_back("tetrahedral meshes (.vtu): no tets_ views");

  // Guidance paths of the guide stage (OUT/paths/<name>.json), in name order.
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
  if (scene.paths.empty()) os.missing.push_back("guidance paths (paths/*.json, the guide stage): the overview has none");

  // Plots: the materials of the attach stage; calibrate / uncertainty results under OUT or named.
  if (flags.plots) {
    for (auto& p : material_plots(out, registry)) scene.plots.push_back(std::move(p));
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
      const bool fit = fs::exists(d / "params.json") && fs::exists(d / "fit.csv");
      const bool mc = fs::exists(d / "summary.json") && fs::exists(d / "cdf.csv");
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
