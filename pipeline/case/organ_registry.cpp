// Over 400 lines: the organ registry (its TOML reader and checks) and the organ regions' materials as
// solver fits and bands, with their JSON for materials.json; one reader of data/organs.toml and its users.
#include "pipeline/case/organ_registry.h"

#include "core/errors.h"
#include "core/toml_parse.h"
#include "physics/materials/presets.h"
#include "physics/materials/material_band.h"
#include "physics/materials/solver_fit.h"
#include "pipeline/output/read_manifest.h"
#include "pipeline/case/stage_options.h"
#include "segmentation/presets.h"

#include <fstream>
#include <mutex>

#include <algorithm>
#include <cmath>
#include <set>

namespace organsmith {

namespace fs = std::filesystem;

std::vector<std::string> OrganInfo::regions() const {
  switch (mesh) {
    case OrganMeshModel::wall_body: return {name + "_wall", name + "_body"};
    case OrganMeshModel::tube:
      if (rings.pitch_mm > 0) return {name + "_cartilage", name + "_membrane"};
      return {name + "_wall"};
    case OrganMeshModel::solid: return {name};
    case OrganMeshModel::none: break;
  }
  return {};
}

std::vector<std::string> OrganInfo::surfaces() const {
  switch (mesh) {
    case OrganMeshModel::wall_body: return {name, name + "_wall_inner"};
    case OrganMeshModel::tube: return {name + "_wall", name + "_lumen"};
    case OrganMeshModel::solid: return {name};
    case OrganMeshModel::none: break;
  }
  return {};
}

std::string OrganInfo::wall_surface() const {
  switch (mesh) {
    case OrganMeshModel::wall_body: return name;
    case OrganMeshModel::tube: return name + "_wall";
    default: return {};
  }
}

std::string_view mesh_model_name(OrganMeshModel m) {
  switch (m) {
    case OrganMeshModel::wall_body: return "wall_body";
    case OrganMeshModel::tube: return "tube";
    case OrganMeshModel::solid: return "solid";
    case OrganMeshModel::none: break;
  }
  return "none";
}

const OrganInfo* OrganRegistry::find(std::string_view name) const {
  for (const auto& o : organs)
    if (o.name == name) return &o;
  return nullptr;
}

const OrganInfo* OrganRegistry::find_label(std::uint8_t label) const {
  for (const auto& o : organs)
    if (o.label == label) return &o;
  return nullptr;
}

std::vector<std::string> OrganRegistry::names() const {
  std::vector<std::string> n;
  for (const auto& o : organs) n.push_back(o.name);
  return n;
}

std::vector<std::string> OrganRegistry::modelled() const {
  std::vector<std::string> n;
  for (const auto& o : organs)
    if (o.mesh != OrganMeshModel::none) n.push_back(o.name);
  return n;
}

std::vector<std::string> OrganRegistry::path_names() const {
  std::vector<std::string> n;
  for (const auto& o : organs)
    for (const auto& kind : o.paths) n.push_back(o.name + "_" + kind);
  return n;
}

std::vector<std::string> OrganRegistry::preferred_path_names() const {
  std::vector<std::string> n;
  for (const char* kind : {"incision", "dissection", "centerline"})
    for (const auto& o : organs)
      if (std::find(o.paths.begin(), o.paths.end(), kind) != o.paths.end()) n.push_back(o.name + "_" + kind);
  for (const auto& name : path_names())  // a kind not above, last
    if (std::find(n.begin(), n.end(), name) == n.end()) n.push_back(name);
  return n;
}

const OrganInfo& OrganRegistry::at(std::string_view name, const fs::path& origin) const {
  if (const OrganInfo* o = find(name)) return *o;
  std::string known;
  for (const auto& n : names()) known += (known.empty() ? "" : ", ") + n;
  throw CaseFileError("unknown organ '" + std::string(name) + "'", origin,
                      "organs of the registry: " + known +
                          "; add one with a registry file ([case] organs = \"my_organs.toml\", see data/organs.toml)");
}

std::string_view builtin_registry_toml() { return default_organ_presets_toml(); }

namespace {

std::string line_of(const toml::node& n) {
  const auto& src = n.source();
  return src.begin ? " (line " + std::to_string(src.begin.line) + ")" : std::string();
}

const std::vector<std::string> kKeys = {"label",          "needs_seed",     "mesh",
                                        "wall_mm",        "materials",      "haptic_surface",
                                        "haptic_region",  "haptic_max_strain", "colour",
                                        "opacity",        "segment",        "rings",
                                        "load_case",      "pressure_kPa",   "probe_diameter_mm",
                                        "paths",          "bed_organ"};

void parse_organ(const std::string& name, const toml::table& t, OrganInfo& o, const fs::path& origin) {
  auto fail = [&](const toml::node& n, const std::string& key, const std::string& what, const std::string& hint) {
    throw CaseFileError("organ registry: [" + name + "] " + key + " " + what + line_of(n), origin, hint);
  };
  for (const auto& [k, n] : t) {
    const std::string key(k.str());
    if (std::find(kKeys.begin(), kKeys.end(), key) == kKeys.end())
      throw CaseFileError("organ registry: unknown key '" + key + "' in [" + name + "]" + line_of(n), origin,
                          "did you mean '" + nearest_key(key, kKeys) + "'? (data/organs.toml explains every key)");
  }
  o.name = name;
  if (const toml::node* n = t.get("label")) {
    const auto v = n->value_exact<std::int64_t>();
    if (!v || *v < 1 || *v > 255) fail(*n, "label", "must be an integer 1–255", "the organ's value in label maps");
    o.label = std::uint8_t(*v);
  }
  if (o.label == 0) throw CaseFileError("organ registry: [" + name + "] has no label", origin, "add label = N (1–255)");
  if (const toml::node* n = t.get("needs_seed")) {
    const auto v = n->value_exact<bool>();
    if (!v) fail(*n, "needs_seed", "must be true or false", "");
    o.needs_seed = *v;
  }
  if (const toml::node* n = t.get("mesh")) {
    const auto v = n->value_exact<std::string>();
    const std::vector<std::string> models = {"wall_body", "tube", "solid", "none"};
    if (!v || std::find(models.begin(), models.end(), *v) == models.end())
      fail(*n, "mesh", "must be one of wall_body, tube, solid, none", "see data/organs.toml");
    o.mesh = *v == "wall_body" ? OrganMeshModel::wall_body
             : *v == "tube"    ? OrganMeshModel::tube
             : *v == "solid"   ? OrganMeshModel::solid
                               : OrganMeshModel::none;
  }
  auto number = [&](const char* key, double& v, double lo, double hi, const char* unit) {
    const toml::node* n = t.get(key);
    if (!n) return;
    const auto x = n->value<double>();
    if (!x || !std::isfinite(*x) || *x < lo || *x > hi)
      fail(*n, key, "must be a number from " + std::to_string(lo) + " to " + std::to_string(hi) + " " + unit, "");
    v = *x;
  };
  number("wall_mm", o.wall_mm, 0.1, 20.0, "mm");
  number("pressure_kPa", o.pressure_kPa, 0.0, 100.0, "kPa");
  number("probe_diameter_mm", o.probe_diameter_mm, 0.5, 50.0, "mm");
  if (const toml::node* n = t.get("load_case")) {
    const auto v = n->value_exact<std::string>();
    if (!v || (*v != "indentation" && *v != "pressure" && *v != "none"))
      fail(*n, "load_case", "must be \"indentation\", \"pressure\" or \"none\"", "see data/organs.toml");
    o.load_case = *v == "none" ? "" : *v;
  }
  if (const toml::node* n = t.get("rings")) {
    const toml::table* r = n->as_table();
    if (!r) fail(*n, "rings", "must be a table { pitch_mm, height_mm, cartilage_arc_deg }", "see data/organs.toml");
    for (const auto& [k, v] : *r) {
      const std::string key(k.str());
      double* dst = key == "pitch_mm" ? &o.rings.pitch_mm : key == "height_mm" ? &o.rings.height_mm
                    : key == "cartilage_arc_deg" ? &o.rings.cartilage_arc_deg : nullptr;
      const auto x = v.value<double>();
      if (!dst) fail(v, "rings." + key, "is not a key of rings", "keys: pitch_mm, height_mm, cartilage_arc_deg");
      if (!x || !std::isfinite(*x) || *x < 0 || *x > 360) fail(v, "rings." + key, "must be a number from 0 to 360", "");
      *dst = *x;
    }
    if (o.rings.pitch_mm > 0 && !(o.rings.height_mm > 0 && o.rings.height_mm < o.rings.pitch_mm))
      fail(*n, "rings", "needs 0 < height_mm < pitch_mm", "e.g. rings = { pitch_mm = 6.1, height_mm = 4.0, cartilage_arc_deg = 270 }");
  }
  number("haptic_max_strain", o.haptic_max_strain, 0.01, 2.0, "");
  number("opacity", o.opacity, 0.0, 1.0, "");
  auto text = [&](const char* key, std::string& v) {
    const toml::node* n = t.get(key);
    if (!n) return;
    const auto x = n->value_exact<std::string>();
    if (!x) fail(*n, key, "must be a string", "");
    v = *x;
  };
  text("haptic_surface", o.haptic_surface);
  text("haptic_region", o.haptic_region);
  text("bed_organ", o.bed_organ);
  if (const toml::node* n = t.get("paths")) {
    const toml::array* a = n->as_array();
    if (!a) fail(*n, "paths", "must be an array of path kinds", "e.g. paths = [\"centerline\", \"incision\"]");
    o.paths.clear();
    for (const auto& item : *a) {
      const auto x = item.value_exact<std::string>();
      if (!x || (*x != "centerline" && *x != "incision" && *x != "dissection"))
        fail(item, "paths", "holds " + (x ? "'" + *x + "'" : std::string("a non-string")) + ", not a path kind",
             "kinds: \"centerline\", \"incision\" (a tube), \"dissection\" (a wall_body)");
      if (std::find(o.paths.begin(), o.paths.end(), *x) == o.paths.end()) o.paths.push_back(*x);
    }
  }
  if (const toml::node* n = t.get("colour")) {
    const toml::array* a = n->as_array();
    bool ok = a && a->size() == 3;
    for (std::size_t i = 0; ok && i < 3; ++i) {
      const auto c = (*a)[i].value<double>();
      ok = c && *c >= 0 && *c <= 1;
      if (ok) o.colour_rgb[i] = *c;
    }
    if (!ok) fail(*n, "colour", "must be [r, g, b] with components in 0–1", "e.g. colour = [0.55, 0.22, 0.17]");
  }
  if (const toml::node* n = t.get("materials")) {
    const toml::table* m = n->as_table();
    if (!m) fail(*n, "materials", "must be a table of region = \"preset id\"", "");
    o.materials.clear();
    for (const auto& [region, id] : *m) {
      const auto v = id.value_exact<std::string>();
      if (!v) fail(id, "materials." + std::string(region.str()), "must be a preset id or a params.json path (a string)", "");
      // A calibration result is named relative to the file that names it.
      o.materials[std::string(region.str())] =
          is_calibration_ref(*v) && !origin.empty() && fs::path(*v).is_relative()
              ? fs::weakly_canonical(fs::absolute(origin).parent_path() / *v).string()
              : *v;
    }
  }
  if (const toml::node* n = t.get("segment"); n && !n->is_table())
    fail(*n, "segment", "must be a table (the segmentation preset)", "write it as [" + name + ".segment]");
  if (t.contains("segment")) o.segmented = true;
}

/// Cross-checks of one organ once every key is known.
void check_organ(const OrganInfo& o, const fs::path& origin) {
  auto fail = [&](const std::string& what, const std::string& hint) {
    throw CaseFileError("organ registry: [" + o.name + "] " + what, origin, hint);
  };
  const auto regions = o.regions();
  const auto surfaces = o.surfaces();
  auto list = [](const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
    return s;
  };
  if ((o.mesh == OrganMeshModel::wall_body || o.mesh == OrganMeshModel::tube) && !(o.wall_mm > 0))
    fail("needs wall_mm (its mesh model has a wall)", "e.g. wall_mm = 2.0");
  for (const auto& [region, _] : o.materials)
    if (std::find(regions.begin(), regions.end(), region) == regions.end())
      fail("materials names region '" + region + "', which its mesh model (" +
               std::string(mesh_model_name(o.mesh)) + ") does not have",
           regions.empty() ? "an organ with mesh = \"none\" takes no materials" : "regions: " + list(regions));
  if (o.rings.pitch_mm > 0 && o.mesh != OrganMeshModel::tube)
    fail("has rings, which only a tube's wall takes", "remove rings, or set mesh = \"tube\"");
  // Every region of a modelled organ carries a calibrated law: a region without one would be
  // written with a placeholder solid, and no answer of the solver would mean anything.
  for (const auto& region : regions)
    if (!o.materials.count(region))
      fail("region " + region + " has no material", "give it a calibrated law: materials = { " + region +
                                                         " = \"<preset id>\" } (`organsmith materials` lists them)");
  for (const auto& [region, id] : o.materials) {
    try {
      (void)region_law(id);
    } catch (const Error& e) {
      fail("material '" + id + "' of region " + region + ": " + e.message(),
           "give a preset id (`organsmith materials` lists them) or the params.json of `organsmith calibrate`");
    }
  }
  if (!o.haptic_surface.empty() && std::find(surfaces.begin(), surfaces.end(), o.haptic_surface) == surfaces.end())
    fail("haptic_surface '" + o.haptic_surface + "' is not one of its surfaces", "surfaces: " + list(surfaces));
  if (!o.haptic_surface.empty() && !o.materials.count(o.haptic_region))
    fail("haptic_region '" + o.haptic_region + "' has no material", "give one of: " + list(regions));
  for (const auto& kind : o.paths) {
    const bool tube_path = kind == "centerline" || kind == "incision";
    if (tube_path && o.mesh != OrganMeshModel::tube)
      fail("paths has '" + kind + "', which only a tube has", "a " + kind + " follows an airway: mesh = \"tube\"");
    if (!tube_path && o.mesh != OrganMeshModel::wall_body)
      fail("paths has '" + kind + "', which only a wall_body has", "a dissection rims the bed of a mesh = \"wall_body\" organ");
  }
  if (!o.bed_organ.empty() && o.mesh != OrganMeshModel::wall_body)
    fail("has a bed_organ, which only a wall_body takes", "remove bed_organ, or set mesh = \"wall_body\"");
}

}  // namespace

OrganRegistry parse_organ_registry(std::string_view text, const fs::path& origin, const OrganRegistry& base) {
  const toml::table root = parse_toml(text, origin, "the organ registry", "fix the syntax (see data/organs.toml)");
  OrganRegistry r = base;
  for (const auto& [k, node] : root) {
    const std::string name(k.str());
    const toml::table* t = node.as_table();
    if (!t) throw CaseFileError("organ registry: '" + name + "' must be a table" + line_of(node), origin,
                                "write each organ as [" + name + "]");
    if (name == kSegmentDefaultsTable) continue;  // not an organ: where the segment tables start (read below)
    OrganInfo* o = const_cast<OrganInfo*>(r.find(name));
    if (!o) o = &r.organs.emplace_back();
    parse_organ(name, *t, *o, origin);
  }
  try {  // the segmentation presets of the `segment` tables: every key known, of its type
    parse_organ_presets(text, default_organ_presets(), PresetText::registry);
  } catch (const Error& e) {
    throw CaseFileError("organ registry: " + e.message(), origin, e.hint());
  }
  std::set<int> labels;
  for (const auto& o : r.organs) {
    check_organ(o, origin);
    if (!o.bed_organ.empty() && (!r.find(o.bed_organ) || o.bed_organ == o.name))
      throw CaseFileError("organ registry: [" + o.name + "] bed_organ '" + o.bed_organ + "' is no other organ of the registry",
                          origin, "organs of the registry: " + [&] {
                            std::string k;
                            for (const auto& n : r.names()) k += (k.empty() ? "" : ", ") + n;
                            return k;
                          }());
    if (!labels.insert(o.label).second)
      throw CaseFileError("organ registry: label " + std::to_string(o.label) + " is used by two organs (one is " +
                              o.name + ")",
                          origin, "give every organ its own label value");
  }
  return r;
}

OrganRegistry registry_of_output(const fs::path& out_dir) {
  const nlohmann::json m = read_manifest(out_dir).value_or(nlohmann::json::object());
  if (!m.contains("case") || !m["case"].is_object() || !m["case"].contains("organ_registry") ||
      !m["case"]["organ_registry"].is_string())
    return builtin_organ_registry();
  const fs::path file = m["case"]["organ_registry"].get<std::string>();
  std::ifstream rf(file, std::ios::binary);
  if (!rf)
    throw InputError(ExitCode::input_not_found, "the organ registry file of this run is gone", file,
                     "restore it, or rerun the case (`organsmith run`)");
  const std::string text((std::istreambuf_iterator<char>(rf)), std::istreambuf_iterator<char>());
  return parse_organ_registry(text, file, builtin_organ_registry());
}

MeshOrganSpec mesh_spec(const OrganInfo& organ, const std::map<std::string, double>& wall_mm) {
  MeshOrganSpec s;
  s.name = organ.name;
  s.label = organ.label;
  s.model = organ.mesh == OrganMeshModel::wall_body ? OrganModel::wall_body
            : organ.mesh == OrganMeshModel::tube    ? OrganModel::tube
                                                    : OrganModel::solid;
  s.wall_mm = organ.wall_mm;
  s.rings = organ.rings;
  s.load_case = organ.load_case;
  s.pressure_kPa = organ.pressure_kPa;
  s.probe_diameter_mm = organ.probe_diameter_mm;
  s.bed_organ = organ.bed_organ;
  if (const auto it = wall_mm.find(organ.name); it != wall_mm.end()) s.wall_mm = it->second;
  return s;
}

bool is_calibration_ref(const std::string& ref) {
  return ref.size() > 5 && ref.compare(ref.size() - 5, 5, ".json") == 0;
}

physics::RegionLaw region_law(const std::string& ref) {
  static const physics::MaterialLibrary lib = physics::builtin_material_library();
  if (is_calibration_ref(ref)) return physics::region_law_from_calibration(ref);
  return physics::region_law_from_preset(lib, ref);
}

namespace {
/// Fits are deterministic and take ~50 ms each; one per material reference and process.
const physics::SolverFit& solver_fit_of(const std::string& ref) {
  static std::mutex mutex;
  static std::map<std::string, physics::SolverFit> cache;
  std::lock_guard lock(mutex);
  auto it = cache.find(ref);
  if (it == cache.end()) it = cache.emplace(ref, physics::fit_solver_material(region_law(ref))).first;
  return it->second;
}

/// Bands take ~0.3 s each (2000 draws, three fits); one per material reference and process.
const physics::MaterialBand& material_band_of(const std::string& ref) {
  static std::mutex mutex;
  static std::map<std::string, physics::MaterialBand> cache;
  std::lock_guard lock(mutex);
  auto it = cache.find(ref);
  if (it == cache.end()) it = cache.emplace(ref, physics::material_band(region_law(ref))).first;
  return it->second;
}

nlohmann::json fit_json(const physics::SolverFit& f) {
  const SolverMaterial& m = f.material;
  nlohmann::json curves = nlohmann::json::array();
  for (const auto& c : f.curves)
    curves.push_back({{"path", c.name}, {"fitted", c.fitted}, {"max_relative_error", c.max_relative_error}});
  nlohmann::json j = {{"form", "ogden"},
          {"convention", "W = sum 2 mu_i/alpha_i^2 (l1^alpha_i + l2^alpha_i + l3^alpha_i - 3) + (J - 1)^2 / D1, D1 = 2/K"},
          {"mu_Pa", m.ogden_mu_Pa},
          {"alpha", m.ogden_alpha},
          {"bulk_modulus_Pa", m.bulk_modulus_Pa},
          {"bulk_source", m.bulk_source},
          {"stretch_range", {1.0, m.stretch_max}},
          {"fitted_to", m.curves},
          {"max_relative_error", m.max_relative_error},
          {"paths", curves},
          {"min_tangent_Pa", f.min_tangent_Pa}};
  // Mooney-Rivlin laws go into INP files as themselves (core/material.h says why).
  if (m.mooney_rivlin_Pa) j["inp"] = {{"form", "mooney-rivlin"}, {"C10_Pa", (*m.mooney_rivlin_Pa)[0]}, {"C01_Pa", (*m.mooney_rivlin_Pa)[1]}};
  return j;
}

/// The first (uniaxial or direction-mean) path of a fit's curves as [[stretch, Pa], …] from (1, 0).
nlohmann::json first_curve_json(const physics::SolverFit& f) {
  const physics::LawCurve& c = f.curves.front();
  nlohmann::json pts = nlohmann::json::array({{1.0, 0.0}});
  for (std::size_t i = 0; i < c.stretch.size(); ++i) pts.push_back({c.stretch[i], c.nominal_stress_Pa[i]});
  return pts;
}
}  // namespace

std::map<std::string, std::map<std::string, SolverMaterial>> region_band_materials(const OrganRegistry& registry,
                                                                                    const std::vector<std::string>& organs) {
  std::map<std::string, std::map<std::string, SolverMaterial>> out;
  for (const auto& name : organs)
    for (const auto& [region, ref] : registry.at(name).materials) {
      const physics::MaterialBand* band = nullptr;
      try {
        band = &material_band_of(ref);
      } catch (const Error& e) {
        throw Error(e.code(), "region " + region + " of " + name + ": " + e.message(), e.path(),
                    "give the region a material with a spread in the case ([materials] " + region +
                        " = …) or leave [stages.mesh] material_band off");
      }
      for (const auto& m : band->members) out[m.name][region] = m.fit.material;
    }
  return out;
}

std::map<std::string, SolverMaterial> region_materials(const OrganRegistry& registry) {
  std::map<std::string, SolverMaterial> out;
  for (const auto& o : registry.organs)
    for (const auto& [region, ref] : o.materials) out[region] = solver_fit_of(ref).material;
  return out;
}

nlohmann::json solver_material_json(const std::string& ref) { return fit_json(solver_fit_of(ref)); }

// The isotropic or direction-mean uniaxial path.
nlohmann::json uniaxial_curve_json(const std::string& ref) { return first_curve_json(solver_fit_of(ref)); }

nlohmann::json materials_json_for(const OrganRegistry& registry, const std::vector<std::string>& organs, bool band) {
  nlohmann::json regions = nlohmann::json::object();
  for (const auto& name : organs) {
    for (const auto& [region, ref] : registry.at(name).materials) {
      const physics::RegionLaw law = region_law(ref);
      nlohmann::json params = nlohmann::json::array();
      for (const auto& p : law.material.parameters)
        params.push_back({{"name", p.name}, {"value", p.value}, {"unit", p.unit}});
      nlohmann::json r = {{is_calibration_ref(ref) ? "calibration" : "preset", ref},
                          {"model", law.material.model},
                          {"parameters", params},
                          {"source", law.material.source},
                          {"stretch_range", {1.0, law.stretch_max}},
                          {"range_source", law.range_source}};
      if (law.material.model == "fung-organ") r["constants"] = {{"bulk_modulus_Pa", law.options.bulk_modulus_Pa}};
      r["uniaxial_curve_pa"] = uniaxial_curve_json(ref);
      r["uniaxial_curve_path"] = solver_fit_of(ref).curves.front().name;
      r["solver"] = solver_material_json(ref);
      if (band) {
        const physics::MaterialBand& b = material_band_of(ref);
        nlohmann::json members = nlohmann::json::object();
        for (const auto& m : b.members)
          members[m.name] = {{"level", m.level}, {"uniaxial_curve_pa", first_curve_json(m.fit)}, {"solver", fit_json(m.fit)}};
        r["band"] = {{"method", "percentiles of the law's stress over Monte Carlo draws of its parameters (independent "
                                "normals), each percentile curve fitted like the law (physics/materials/material_band.h)"},
                     {"spread", b.spread_kind},
                     {"draws", b.draws},
                     {"rejected_draws", b.rejected_draws},
                     {"members", members}};
      }
      regions[region] = r;
    }
  }
  return {{"regions", regions}};
}

const OrganRegistry& builtin_organ_registry() {
  static const OrganRegistry r = parse_organ_registry(builtin_registry_toml(), "data/organs.toml (embedded)");
  return r;
}

}  // namespace organsmith
