// Case files: parsing and validating every table of a case, and its JSON form. Over 400 lines for a
// reason: it is the one place that knows every key a case may hold and checks each against its
// rules, so that an unknown or wrong key never falls back to a default silently.
#include "pipeline/case/case_file.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "core/toml_parse.h"
#include "default_case_toml.h"  // generated from data/default_case.toml
#include "pipeline/case/stage_options_toml.h"
#include "pacs/pacs.h"
#include "segmentation/presets.h"

#include <toml++/toml.h>

#include <algorithm>
#include <set>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

std::string where(const toml::node& n) {
  const auto& src = n.source();
  return src.begin ? " (line " + std::to_string(src.begin.line) + ")" : std::string();
}

/// Reads a table and rejects keys it does not know, so that a typo never silently falls back
/// to a default.
class Table {
 public:
  Table(const toml::table* t, std::string name, fs::path origin)
      : t_(t), name_(std::move(name)), origin_(std::move(origin)) {}

  void only(const std::set<std::string>& keys) const {
    if (!t_) return;
    for (const auto& [k, v] : *t_) {
      if (!keys.count(std::string(k.str()))) {
        std::string known;
        for (const auto& key : keys) known += (known.empty() ? "" : ", ") + key;
        throw CaseFileError("unknown key '" + std::string(k.str()) + "' in [" + name_ + "]" + where(v),
                            origin_, "known keys: " + known);
      }
    }
  }

  template <typename T>
  void get(const char* key, T& out) const {
    if (!t_) return;
    const toml::node* n = t_->get(key);
    if (!n) return;
    if constexpr (std::is_same_v<T, bool>) {
      if (auto v = n->value_exact<bool>()) return void(out = *v);
    } else if constexpr (std::is_integral_v<T>) {
      if (auto v = n->value_exact<std::int64_t>()) return void(out = T(*v));
    } else if constexpr (std::is_floating_point_v<T>) {
      if (auto v = n->value<double>()) return void(out = T(*v));
    } else {
      if (auto v = n->value_exact<std::string>()) return void(out = *v);
    }
    throw CaseFileError("[" + name_ + "] " + key + " has the wrong type" + where(*n), origin_,
                        std::string("expected ") + type_name<T>());
  }

  std::optional<Eigen::Vector3d> vec3(const char* key) const {
    if (!t_) return std::nullopt;
    const toml::node* n = t_->get(key);
    if (!n) return std::nullopt;
    const toml::array* a = n->as_array();
    Eigen::Vector3d v;
    if (a && a->size() == 3) {
      bool ok = true;
      for (int i = 0; i < 3; ++i) {
        auto x = (*a)[std::size_t(i)].value<double>();
        ok = ok && x.has_value();
        if (x) v[i] = *x;
      }
      if (ok) return v;
    }
    throw CaseFileError("[" + name_ + "] " + key + " must be an array of three numbers" + where(*n),
                        origin_, std::string("e.g. ") + key + " = [12.5, -40.0, 310.0]");
  }

 private:
  template <typename T>
  static const char* type_name() {
    if constexpr (std::is_same_v<T, bool>) return "true or false";
    else if constexpr (std::is_integral_v<T>) return "an integer";
    else if constexpr (std::is_floating_point_v<T>) return "a number";
    else return "a string";
  }
  const toml::table* t_;
  std::string name_;
  fs::path origin_;
};

void fail_if(bool bad, const std::string& what, const fs::path& origin, const std::string& hint) {
  if (bad) throw CaseFileError(what, origin, hint);
}

}  // namespace

/// The 1-based line of the first byte that is not UTF-8, or 0 when the text is valid UTF-8.
static std::size_t first_invalid_utf8_line(const std::string& text) {
  std::size_t line = 1;
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    const int n = c < 0x80 ? 0 : (c >> 5) == 0x6 ? 1 : (c >> 4) == 0xE ? 2 : (c >> 3) == 0x1E ? 3 : -1;
    if (n < 0 || i + std::size_t(n) >= text.size() + (n == 0 ? 1 : 0)) return line;
    for (int k = 1; k <= n; ++k)
      if ((static_cast<unsigned char>(text[i + std::size_t(k)]) >> 6) != 0x2) return line;
    if (c == '\n') ++line;
    i += std::size_t(n) + 1;
  }
  return 0;
}

/// input = "pacs://<name>/<StudyInstanceUID>" with its [pacs.<name>] table.
static PacsSource pacs_source(const toml::table& root, const std::string& input, const fs::path& base,
                              const fs::path& origin) {
  PacsSource p;
  const std::string rest = input.substr(7);
  const auto slash = rest.find('/');
  p.name = rest.substr(0, slash);
  p.study_uid = slash == std::string::npos ? "" : rest.substr(slash + 1);
  const bool uid_ok = !p.study_uid.empty() && p.study_uid.size() <= 64 &&
                      p.study_uid.find_first_not_of("0123456789.") == std::string::npos;
  fail_if(p.name.empty() || !uid_ok, "[case] input '" + input + "' is no PACS study", origin,
          "write input = \"pacs://<name>/<StudyInstanceUID>\" with a [pacs.<name>] table");
  const toml::table* all = root["pacs"].as_table();
  const toml::table* t = all ? (*all)[p.name].as_table() : nullptr;
  fail_if(!t, "[case] input names the PACS '" + p.name + "' but the case has no [pacs." + p.name + "] table", origin,
          "add [pacs." + p.name + "] with url = \"http://host:8042/dicom-web\" (or \"dicom://AET@host:104\")");
  Table pt(t, "pacs." + p.name, origin);
  pt.only({"url", "calling_aet", "ca_file", "cache", "timeout_s", "retries", "move_port"});
  std::string cache, ca;
  pt.get("url", p.url);
  pt.get("calling_aet", p.calling_aet);
  pt.get("ca_file", ca);
  pt.get("cache", cache);
  pt.get("timeout_s", p.timeout_s);
  pt.get("retries", p.retries);
  pt.get("move_port", p.move_port);
  fail_if(p.move_port < 0 || p.move_port > 65535, "[pacs." + p.name + "] move_port must be 0–65535", origin,
          "0 (the default) retrieves by C-GET");
  try {
    (void)parse_pacs_url(p.url, p.calling_aet);
  } catch (const Error& e) {
    throw CaseFileError("[pacs." + p.name + "] " + e.message(), origin, e.hint());
  }
  fail_if(!(p.timeout_s >= 1 && p.timeout_s <= 3600), "[pacs." + p.name + "] timeout_s must be 1–3600", origin, "60 is the default");
  fail_if(p.retries < 0 || p.retries > 20, "[pacs." + p.name + "] retries must be 0–20", origin, "3 is the default");
  if (!ca.empty()) p.ca_file = fs::weakly_canonical(base / ca);
  if (!cache.empty()) {
    p.cache_dir = fs::weakly_canonical(base / cache);
  } else {
    const char* xdg = std::getenv("XDG_CACHE_HOME");
    const char* home = std::getenv("HOME");
    p.cache_dir = xdg && *xdg ? fs::path(xdg) / "organsmith" / "pacs"
                  : home      ? fs::path(home) / ".cache" / "organsmith" / "pacs"
                              : fs::temp_directory_path() / "organsmith-pacs";
  }
  return p;
}

CaseFile parse_case(const std::string& text, const fs::path& origin) {
  if (const std::size_t bad = first_invalid_utf8_line(text))
    throw CaseFileError("the case file is not UTF-8 text (line " + std::to_string(bad) + ")", origin,
                        "save it as UTF-8 (a case file is TOML)");
  toml::table root = parse_toml(text, origin, "the case file", "fix the syntax (see README.md, 'Case file')");
  if (root.empty())
    throw CaseFileError("the case file is empty", origin,
                        "start from `organsmith run --print-default-case` (a case needs at least [case] input)");
  CaseFile c;
  c.source = origin;
  const fs::path base = origin.empty() ? fs::current_path() : fs::absolute(origin).parent_path();

  Table(&root, "top level", origin).only({"case", "phantom", "ingest", "organ", "output", "stages", "materials", "pacs"});

  Table cs(root["case"].as_table(), "case", origin);
  cs.only({"name", "input", "organs"});
  std::string input = "phantom", registry_file;
  cs.get("name", c.name);
  cs.get("input", input);
  cs.get("organs", registry_file);
  if (!registry_file.empty()) {
    c.registry_file = fs::weakly_canonical(base / registry_file);
    const auto text = read_file(c.registry_file);
    if (!text)
      throw CaseFileError("cannot read the organ registry file " + c.registry_file.string() + " ([case] organs)",
                          origin, "give a TOML file laid out like data/organs.toml, relative to the case file");
    c.registry = parse_organ_registry(*text, c.registry_file, builtin_organ_registry());
    c.registry_toml = *text;
  }
  if (const toml::node* mats = root.get("materials")) {
    // [materials] region = "preset id" | "calibration/params.json": the region's law, replacing
    // the registry's. Paths are relative to the case file.
    const toml::table* mt = mats->as_table();
    fail_if(!mt, "[materials] must be a table of region = \"preset id or params.json\"" + where(*mats), origin,
            "e.g. [materials] gallbladder_wall = \"my_fit/params.json\"");
    for (const auto& [key, node] : *mt) {
      const std::string region(key.str());
      const auto v = node.value_exact<std::string>();
      fail_if(!v, "[materials] " + region + " must be a string" + where(node), origin,
              "a preset id (`organsmith materials`) or the params.json of `organsmith calibrate`");
      OrganInfo* owner = nullptr;
      std::string known;
      for (auto& o : c.registry.organs)
        for (const auto& r : o.regions()) {
          known += (known.empty() ? "" : ", ") + r;
          if (r == region) owner = &o;
        }
      fail_if(!owner, "[materials] names region '" + region + "', which no organ has" + where(node), origin,
              "regions: " + known);
      std::string ref = *v;
      if (is_calibration_ref(ref) && fs::path(ref).is_relative()) ref = fs::weakly_canonical(base / ref).string();
      try {
        (void)region_law(ref);
      } catch (const Error& e) {
        throw CaseFileError("[materials] " + region + ": " + e.message() + where(node), origin,
                            "give a preset id (`organsmith materials` lists them) or the params.json of `organsmith calibrate`");
      }
      owner->materials[region] = ref;
      c.material_overrides[region] = ref;
    }
  }
  fail_if(input.empty(), "[case] input is empty", origin,
          "give \"phantom\" or a DICOM directory / NIfTI / NRRD / MHA path");
  c.synthesize_phantom = input == "phantom";
  if (input.rfind("pacs://", 0) == 0) {
    c.pacs = pacs_source(root, input, base, origin);
    c.input = cached_study_dir(c.pacs->cache_dir, c.pacs->study_uid);
  } else if (!c.synthesize_phantom) {
    c.input = fs::weakly_canonical(base / input);
  }

  Table ph(root["phantom"].as_table(), "phantom", origin);
  ph.only({"seed", "size", "slice_mm", "fov_mm", "extent_mm", "noise_hu", "blur_mm"});
  ph.get("seed", c.phantom.seed);
  ph.get("size", c.phantom.size_vox);
  ph.get("slice_mm", c.phantom.slice_mm);
  ph.get("fov_mm", c.phantom.fov_mm);
  ph.get("extent_mm", c.phantom.extent_mm);
  ph.get("noise_hu", c.phantom.noise_hu);
  ph.get("blur_mm", c.phantom.blur_mm);
  fail_if(c.phantom.size_vox < 32 || c.phantom.size_vox > 2048, "[phantom] size must be 32–2048",
          origin, "512 is the default");
  fail_if(!(c.phantom.slice_mm > 0.1 && c.phantom.slice_mm <= 20), "[phantom] slice_mm must be in (0.1, 20]",
          origin, "2.5 is the default");

  Table in(root["ingest"].as_table(), "ingest", origin);
  in.only({"series", "allow_modality", "max_memory_mb", "spacing_tolerance", "tilt_tolerance_deg"});
  std::int64_t max_mb = 0;
  in.get("series", c.ingest.series_uid);
  in.get("allow_modality", c.ingest.allow_modality);
  in.get("max_memory_mb", max_mb);
  in.get("spacing_tolerance", c.ingest.spacing_tolerance);
  in.get("tilt_tolerance_deg", c.ingest.tilt_tolerance_deg);
  fail_if(max_mb < 0, "[ingest] max_memory_mb must be ≥ 0", origin, "0 means 60 % of physical memory");
  c.ingest.max_memory_bytes = max_mb << 20;

  if (const toml::node* organs = root.get("organ")) {
    const toml::array* arr = organs->as_array();
    fail_if(!arr, "'organ' must be an array of tables ([[organ]])" + where(*organs), origin,
            "write each organ as [[organ]] followed by name = \"…\"");
    for (const auto& node : *arr) {
      const toml::table* t = node.as_table();
      fail_if(!t, "each [[organ]] entry must be a table" + where(node), origin, "");
      Table ot(t, "organ", origin);
      ot.only({"name", "seed_lps_mm", "seed_ijk", "label_map"});
      OrganSpec o;
      ot.get("name", o.name);
      std::string label_map;
      ot.get("label_map", label_map);
      const OrganInfo* info = c.registry.find(o.name);
      std::string modelled;
      for (const auto& n : c.registry.modelled()) modelled += (modelled.empty() ? "" : ", ") + n;
      fail_if(!info || info->mesh == OrganMeshModel::none, "unknown organ '" + o.name + "'" + where(node), origin,
              "organs with a model: " + modelled +
                  "; add one with an organ registry file ([case] organs = \"my_organs.toml\", see data/organs.toml)");
      if (!label_map.empty()) o.label_map = label_map == "phantom" ? fs::path("phantom") : fs::weakly_canonical(base / label_map);
      else if (!info->segmented && c.synthesize_phantom) o.label_map = "phantom";
      fail_if(o.label_map.empty() && !info->segmented,
              "organ '" + o.name + "' has no segmentation preset and no label map" + where(node), origin,
              "give label_map = \"FILE\" (a label map on the input's grid holding it as label " +
                  std::to_string(info->label) + ")");
      o.seed_lps_mm = ot.vec3("seed_lps_mm");
      o.seed_ijk = ot.vec3("seed_ijk");
      fail_if(o.seed_lps_mm && o.seed_ijk, "organ '" + o.name + "' has both seed_lps_mm and seed_ijk",
              origin, "give one of them");
      for (const auto& other : c.organs)
        fail_if(other.name == o.name, "organ '" + o.name + "' is listed twice", origin, "list each organ once");
      c.organs.push_back(std::move(o));
    }
  }

  Table out(root["output"].as_table(), "output", origin);
  out.only({"dir"});
  std::string dir = "out";
  out.get("dir", dir);
  c.out_dir = origin.empty() ? fs::path(dir) : base / dir;

  const toml::table* stages = root["stages"].as_table();
  if (const toml::node* n = root.get("stages"); n && !stages)
    throw CaseFileError("'stages' must be a table" + where(*n), origin, "write [stages.<stage>] tables");
  c.stages = parse_stage_options(stages, origin);
  for (const auto& [organ, mm] : c.stages.mesh.wall_mm) {
    const OrganInfo* info = c.registry.find(organ);
    fail_if(!info || (info->mesh != OrganMeshModel::wall_body && info->mesh != OrganMeshModel::tube),
            "[stages.mesh] wall_mm names '" + organ + "', which is no organ with a wall", origin,
            "organs with a wall have mesh = \"wall_body\" or \"tube\" in the organ registry");
  }
  for (const auto& [organ, kpa] : c.stages.mesh.pressure_kPa) {
    const OrganInfo* info = c.registry.find(organ);
    fail_if(!info || (info->mesh != OrganMeshModel::wall_body && info->mesh != OrganMeshModel::tube),
            "[stages.mesh] pressure_kPa names '" + organ + "', which is no organ with a lumen", origin,
            "organs with a lumen have mesh = \"wall_body\" or \"tube\" in the organ registry");
  }
  // Organ lists: the organs must be the registry's, with a wall (solver load cases are made for
  // wall_body and tube organs), and an organ pressed in a snapshot must have the probe as its load
  // case (the registry's, or [stages.mesh] indentation).
  const auto has_wall = [&](const std::string& organ) {
    const OrganInfo* info = c.registry.find(organ);
    return info && (info->mesh == OrganMeshModel::wall_body || info->mesh == OrganMeshModel::tube);
  };
  const std::string wall_hint = "organs with a wall have mesh = \"wall_body\" or \"tube\" in the organ registry";
  for (const auto& organ : c.stages.mesh.indentation)
    fail_if(!has_wall(organ), "[stages.mesh] indentation names '" + organ + "', which is no organ with a wall", origin,
            wall_hint);
  for (const auto& organ : c.stages.simulate.organs)
    fail_if(!has_wall(organ), "[stages.simulate] organs names '" + organ + "', which is no organ with a load case",
            origin, wall_hint);
  for (const auto& organ : c.stages.snapshot.indent) {
    const auto& ind = c.stages.mesh.indentation;
    const bool pressed = std::find(ind.begin(), ind.end(), organ) != ind.end() ||
                         (has_wall(organ) && c.registry.find(organ)->load_case == "indentation" &&
                          !c.stages.mesh.pressure_kPa.count(organ));
    fail_if(!has_wall(organ) || !pressed,
            "[stages.snapshot] indent names '" + organ + "', whose load case is not the probe", origin,
            "an organ is pressed when its registry's load_case is \"indentation\" or [stages.mesh] indentation names it");
  }
  const std::vector<std::string> path_names = c.registry.path_names();
  for (const auto& path : c.stages.guide.only)
    fail_if(std::find(path_names.begin(), path_names.end(), path) == path_names.end(),
            "[stages.guide] paths names '" + path + "', which no organ of the registry has", origin,
            "paths of the organ registry: " + [&] {
              std::string k;
              for (const auto& n : path_names) k += (k.empty() ? "" : ", ") + n;
              return k;
            }());
  if (const toml::table* presets = root["stages"]["segment"]["presets"].as_table()) {
    std::ostringstream ts;
    ts << toml::toml_formatter{*presets};
    set_segment_presets(c, ts.str(), origin);
  } else if (const toml::node* p = root["stages"]["segment"]["presets"].node()) {
    throw CaseFileError("[stages.segment] presets must be a table" + where(*p), origin,
                        "write [stages.segment.presets.<organ>] tables");
  }
  // Last, so that every other mistake of a fragment is named first.
  if (!root["case"]["input"])
    throw CaseFileError("the case names no input ([case] input)", origin,
                        "give input = \"scans/…\" (DICOM, NIfTI, NRRD, MHA) or input = \"phantom\"");
  return c;
}

void set_segment_presets(CaseFile& c, const std::string& toml_text, const fs::path& origin) {
  try {
    parse_organ_presets(toml_text, default_organ_presets());
  } catch (const Error& e) {
    throw CaseFileError(e.message() + " (in the segmentation presets)", origin, e.hint());
  }
  const toml::table t = parse_toml(toml_text, origin, "the segmentation presets", "");
  std::ostringstream js;
  js << toml::json_formatter{t};
  c.segment_presets_toml = toml_text;
  c.segment_presets = nlohmann::json::parse(js.str());
}

CaseFile load_case_file(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec))
    throw InputError(ExitCode::input_not_found, "the case file does not exist", path,
                     "check the path; `organsmith run` without a case runs the embedded default");
  if (!fs::is_regular_file(path, ec))
    throw InputError(ExitCode::input_not_found, "the case file is not a regular file", path,
                     "give a TOML file (see `organsmith run --print-default-case`)");
  const auto text = read_file(path);
  if (!text)
    throw InputError(ExitCode::input_not_found, "cannot read the case file", path, "check its permissions");
  return parse_case(*text, path);
}

const std::string& default_case_text() {
  static const std::string text(kDefaultCaseToml);
  return text;
}

CaseFile default_case() {
  CaseFile c = parse_case(default_case_text(), {});
  c.source.clear();
  return c;
}

nlohmann::json to_json(const CaseFile& c) {
  nlohmann::json j;
  j["name"] = c.name;
  j["input"] = c.synthesize_phantom ? std::string("phantom") : c.input.string();
  // A PACS study is recorded by its cache folder and the hash of its UID, never the UID.
  if (c.pacs) j["pacs"] = {{"name", c.pacs->name}, {"url", c.pacs->url}, {"study_key", uid_key(c.pacs->study_uid)}};
  j["phantom"] = {{"seed", c.phantom.seed},          {"size_vox", c.phantom.size_vox},
                  {"slice_mm", c.phantom.slice_mm},  {"fov_mm", c.phantom.fov_mm},
                  {"extent_mm", c.phantom.extent_mm}, {"blur_mm", c.phantom.blur_mm},
                  {"noise_hu", c.phantom.noise_hu}};
  j["ingest"] = {{"series", c.ingest.series_uid},
                 {"allow_modality", c.ingest.allow_modality},
                 {"max_memory_mb", c.ingest.max_memory_bytes >> 20},
                 {"spacing_tolerance", c.ingest.spacing_tolerance},
                 {"gap_factor", c.ingest.gap_factor},
                 {"tilt_tolerance_deg", c.ingest.tilt_tolerance_deg}};
  j["organs"] = nlohmann::json::array();
  for (const auto& o : c.organs) {
    nlohmann::json oj = {{"name", o.name}};
    if (o.seed_lps_mm) oj["seed_lps_mm"] = {o.seed_lps_mm->x(), o.seed_lps_mm->y(), o.seed_lps_mm->z()};
    if (o.seed_ijk) oj["seed_ijk"] = {o.seed_ijk->x(), o.seed_ijk->y(), o.seed_ijk->z()};
    if (!o.label_map.empty()) oj["label_map"] = o.label_map.string();
    j["organs"].push_back(oj);
  }
  j["output"] = {{"dir", c.out_dir.string()}};
  if (!c.registry_file.empty()) j["organ_registry"] = c.registry_file.string();
  if (!c.material_overrides.empty()) j["materials"] = c.material_overrides;
  j["stages"] = nlohmann::json::object();
  for (const auto& stage : configurable_stages()) j["stages"][stage] = stage_json(c, stage);
  return j;
}

nlohmann::json stage_json(const CaseFile& c, const std::string& stage) {
  if (stage == "segment") return {{"presets", c.segment_presets}};
  return stage_options_json(c.stages, stage);
}

std::string default_case_with_options_text() { return default_case_text() + "\n" + describe_stage_options(); }

}  // namespace organsmith
