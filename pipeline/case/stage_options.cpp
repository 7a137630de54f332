// [stages.*] options: one list of fields per stage (`visit`) and the visitors that parse, print
// and turn them into JSON. Over 400 lines because the field lists and their three visitors are one
// table read four ways; split, a new option would have to be added in several files.

#include "pipeline/case/stage_options.h"

#include "core/errors.h"
#include "core/format.h"
#include "meshing/export.h"
#include "pipeline/case/stage_options_toml.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

namespace organsmith {



namespace fs = std::filesystem;

MeshStageOptions::MeshStageOptions() : formats(all_mesh_formats()) {}

namespace {

const std::vector<std::string> kViews = {"organs", "overview", "slices", "tets", "plots"};

/// One list of fields per stage; each visitor does one job with it (parse, print, to JSON).
class Visitor {
 public:
  virtual ~Visitor() = default;
  virtual void number(const char* key, double& v, double lo, double hi, const char* unit, const char* doc) = 0;
  virtual void integer(const char* key, int& v, int lo, int hi, const char* doc) = 0;
  virtual void boolean(const char* key, bool& v, const char* doc) = 0;
  virtual void choice(const char* key, std::string& v, const std::vector<std::string>& allowed, const char* doc) = 0;
  virtual void subset(const char* key, std::vector<std::string>& v, const std::vector<std::string>& allowed,
                      const char* doc) = 0;
  /// A list of organ names (checked against the registry by the caller: the case's own registry
  /// is known only there).
  virtual void organs(const char* key, std::vector<std::string>& v, const char* doc) { names(key, v, "organ", doc); }
  /// A list of names the organ registry defines (`what`: "organ", "path"; checked by the caller).
  virtual void names(const char* key, std::vector<std::string>& v, const char* what, const char* doc) = 0;
  /// A table of organ name → number (organ names are checked against the registry by the caller).
  virtual void per_organ(const char* key, std::map<std::string, double>& v, double lo, double hi, const char* unit,
                         const char* doc) = 0;
  /// A point [x, y, z] (LPS mm), or [] for none.
  virtual void point(const char* key, std::vector<double>& v, const char* doc) = 0;
};

void visit(Visitor& v, MeshStageOptions& o) {
  v.number("edge_mm", o.edge_mm, 0.3, 10.0, "mm", "target surface edge length");
  v.number("tet_edge_mm", o.tet_edge_mm, 0.0, 20.0, "mm",
           "edge of the tetrahedral meshes (solver files, real-time model); 0 = edge_mm; default 4.5 (the default case's gallbladder: ~4 000 C3D10 nodes)");
  v.per_organ("wall_mm", o.wall_mm, 0.5, 8.0, "mm", "wall thickness per organ, e.g. { gallbladder = 3.0 }; "
                                                    "{} = the organ registry's");
  v.boolean("tetrahedra", o.tetrahedra, "also build tetrahedral meshes");
  v.subset("formats", o.formats, all_mesh_formats(), "export formats");
  v.boolean("ras", o.ras, "write RAS instead of LPS coordinates");
  v.choice("quality_gate", o.quality_gate, {"report", "enforce"},
           "a mesh still missing a quality gate after meshing's remedies: enforce (stop, exit 61; default) or report "
           "(warn, quality.json)");
  v.boolean("linear_tets", o.linear_tets, "linear tetrahedra (C3D4/tet4) instead of quadratic (C3D10/tet10)");
  v.organs("indentation", o.indentation,
           "organs with a wall pressed by the thesis' rigid probe instead of a pressure, e.g. [\"trachea\"] (its anterior wall "
           "halfway between the cuts, both cuts held); [] = each organ's registry load case");
  v.per_organ("pressure_kPa", o.pressure_kPa, 0.0, 100.0, "kPa",
              "a lumen pressure load step for the organs named, e.g. { trachea = 1.0 } (for the gallbladder instead of "
              "its indentation); {} = each organ's registry load case (gallbladder: the 5 mm probe; trachea: 2 kPa)");
  v.number("max_fold_deg", o.max_fold_deg, 0.0, 180.0, "deg",
           "fold gate of an organ's uncut outer surface: largest angle between neighbouring triangles (default 60; 0 = off): a crease "
           "the surface edge cannot carry, which a solver's elements buckle at");
  v.boolean("material_band", o.material_band,
            "also write each organ's INP with the P5/P50/P95 variants of its materials (meshes/<organ>/band/)");
}

void visit(Visitor& v, SimulateStageOptions& o) {
  v.boolean("enabled", o.enabled, "run the organs' load cases in CalculiX during `run`");
  v.organs("organs", o.organs, "organs with a wall to simulate; [] = every organ with a load case");
  v.integer("threads", o.threads, 0, 1024, "solver threads; 0 = every core");
  v.number("timeout_s", o.timeout_s, 0.0, 1.0e6, "s", "stop a solver run after this long; 0 = no limit");
  v.boolean("band", o.band, "also run the material band's variants ([stages.mesh] material_band) and report a band");
  v.point("probe_lps_mm", o.probe_lps_mm,
          "where the indentation probe touches the gallbladder, [x, y, z] LPS mm (snapped to its free surface); [] = the "
          "centre of the surface opposite the liver bed");
  v.number("probe_depth_mm", o.probe_depth_mm, 0.0, 100.0, "mm",
           "depth the probe's step presses to; 0 = a fifth of the organ's thickness under it (the curve ends earlier "
           "where a region reaches its calibrated range)");
}

void visit(Visitor& v, GuideStageOptions& o) {
  v.names("paths", o.only, "path", "guidance paths to make (<organ>_<kind>); [] = every path whose organ is there");
  v.integer("first_ring", o.incision.first_ring, 1, 40, "incision: first ring from the cranial end");
  v.integer("ring_count", o.incision.ring_count, 1, 40, "incision: rings spanned");
  v.number("ring_pitch_mm", o.incision.ring_pitch_mm, 1.0, 30.0, "mm", "incision: cartilage ring period");
  v.number("bed_distance_mm", o.dissection.bed_distance_mm, 0.1, 20.0, "mm",
           "dissection: surface within this distance of the liver is liver bed");
  v.boolean("bed_from_ct", o.dissection.bed_from_ct,
            "dissection without a liver label: find the liver bed in the CT (else: the surface facing up and right)");
  v.number("centerline_spacing_mm", o.centerline.spacing_mm, 0.1, 10.0, "mm", "centreline point spacing");
}

void visit(Visitor& v, SnapshotStageOptions& o) {
  v.integer("width_px", o.width_px, 64, 8192, "PNG width, pixels");
  v.integer("height_px", o.height_px, 64, 8192, "PNG height, pixels");
  v.subset("views", o.views, kViews, "views to draw");
  v.organs("indent", o.indent,
           "organs whose load case is the probe, pressed by the simulate stage's 5 mm probe through organsmith's finite-element model and drawn "
           "deformed, coloured by stress (snapshots/indent_<organ>.png; about 30 s each); [] = none");
}

template <typename F>
void for_each_stage(StageOptions& o, F&& f) {
  f("segment", nullptr);
  f("mesh", [&](Visitor& v) { visit(v, o.mesh); });
  f("attach", nullptr);
  f("guide", [&](Visitor& v) { visit(v, o.guide); });
  f("simulate", [&](Visitor& v) { visit(v, o.simulate); });
  f("snapshot", [&](Visitor& v) { visit(v, o.snapshot); });
}

std::string join(const std::vector<std::string>& items, const char* sep = ", ") {
  std::string s;
  for (const auto& i : items) s += (s.empty() ? "" : sep) + i;
  return s;
}

std::string line_of(const toml::node& n) {
  const auto& src = n.source();
  return src.begin ? " (line " + std::to_string(src.begin.line) + ")" : std::string();
}

/// Reads one stage's table: every key must be a field, of its type, inside its range.
class Parser final : public Visitor {
 public:
  Parser(const toml::table& t, std::string stage, fs::path origin)
      : t_(t), stage_(std::move(stage)), origin_(std::move(origin)) {}

  void number(const char* key, double& v, double lo, double hi, const char* unit, const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const auto x = n->value<double>();
    if (!x) fail(*n, key, "must be a number", std::string("a number of ") + unit);
    if (!std::isfinite(*x) || *x < lo || *x > hi)
      fail(*n, key, "is " + format_g(*x, 6) + ", out of range",
           "allowed: " + format_g(lo, 6) + " to " + format_g(hi, 6) + " " + unit);
    v = *x;
  }
  void integer(const char* key, int& v, int lo, int hi, const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const auto x = n->value_exact<std::int64_t>();
    if (!x) fail(*n, key, "must be an integer", "e.g. " + std::to_string(v));
    if (*x < lo || *x > hi)
      fail(*n, key, "is " + std::to_string(*x) + ", out of range",
           "allowed: " + std::to_string(lo) + " to " + std::to_string(hi));
    v = int(*x);
  }
  void boolean(const char* key, bool& v, const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const auto x = n->value_exact<bool>();
    if (!x) fail(*n, key, "must be true or false", "");
    v = *x;
  }
  void choice(const char* key, std::string& v, const std::vector<std::string>& allowed, const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const auto x = n->value_exact<std::string>();
    if (!x || std::find(allowed.begin(), allowed.end(), *x) == allowed.end())
      fail(*n, key, x ? "is '" + *x + "', not an allowed value" : "must be a string", "allowed: " + join(allowed));
    v = *x;
  }
  void subset(const char* key, std::vector<std::string>& v, const std::vector<std::string>& allowed,
              const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const toml::array* a = n->as_array();
    if (!a) fail(*n, key, "must be an array of strings", "e.g. " + std::string(key) + " = [\"" + allowed.front() + "\"]");
    std::vector<std::string> out;
    for (const auto& item : *a) {
      const auto x = item.value_exact<std::string>();
      if (!x || std::find(allowed.begin(), allowed.end(), *x) == allowed.end())
        fail(item, key, x ? "holds '" + *x + "', not an allowed value" : "must hold strings only",
             "allowed: " + join(allowed));
      if (std::find(out.begin(), out.end(), *x) == out.end()) out.push_back(*x);
    }
    v = out;
  }

  void names(const char* key, std::vector<std::string>& v, const char* what, const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const toml::array* a = n->as_array();
    const std::string example = std::string(what) == "path" ? "trachea_centerline" : "trachea";
    if (!a) fail(*n, key, "must be an array of " + std::string(what) + " names", "e.g. " + std::string(key) + " = [\"" + example + "\"]");
    std::vector<std::string> out;
    for (const auto& item : *a) {
      const auto x = item.value_exact<std::string>();
      if (!x) fail(item, key, "must hold " + std::string(what) + " names (strings) only", "e.g. " + std::string(key) + " = [\"" + example + "\"]");
      if (std::find(out.begin(), out.end(), *x) == out.end()) out.push_back(*x);
    }
    v = out;
  }

  void per_organ(const char* key, std::map<std::string, double>& v, double lo, double hi, const char* unit,
                 const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const toml::table* t = n->as_table();
    if (!t) fail(*n, key, "must be a table of organ = number", "e.g. " + std::string(key) + " = { gallbladder = 3.0 }");
    v.clear();
    for (const auto& [organ, value] : *t) {
      const auto x = value.value<double>();
      if (!x || !std::isfinite(*x) || *x < lo || *x > hi)
        fail(value, (std::string(key) + "." + std::string(organ.str())).c_str(), "is not a number in range",
             "allowed: " + format_g(lo, 6) + " to " + format_g(hi, 6) + " " + unit);
      v[std::string(organ.str())] = *x;
    }
  }

  void point(const char* key, std::vector<double>& v, const char*) override {
    const toml::node* n = take(key);
    if (!n) return;
    const toml::array* a = n->as_array();
    if (!a || (a->size() != 3 && a->size() != 0)) fail(*n, key, "must be [x, y, z] (LPS mm) or []", "e.g. [12.5, -40.0, 101.0]");
    std::vector<double> out;
    for (const auto& item : *a) {
      const auto x = item.value<double>();
      if (!x || !std::isfinite(*x) || std::abs(*x) > 1e5) fail(item, key, "must hold three finite numbers (mm)", "");
      out.push_back(*x);
    }
    v = out;
  }

  /// After the visit: a key no field took is a typo or an option of another stage.
  void reject_unknown(const std::set<std::string>& also_allowed = {}) const {
    std::vector<std::string> valid = known_;
    for (const auto& k : also_allowed) valid.push_back(k);
    for (const auto& [k, node] : t_) {
      const std::string key(k.str());
      if (std::find(valid.begin(), valid.end(), key) != valid.end()) continue;
      throw CaseFileError("unknown key '" + key + "' in [stages." + stage_ + "]" + line_of(node), origin_,
                          valid.empty() ? "[stages." + stage_ + "] takes no options in this version"
                                        : "did you mean '" + nearest_key(key, valid) + "'? keys: " + join(valid));
    }
  }

 private:
  const toml::node* take(const char* key) {
    known_.push_back(key);
    return t_.get(key);
  }
  [[noreturn]] void fail(const toml::node& n, const char* key, const std::string& what, const std::string& hint) const {
    throw CaseFileError("[stages." + stage_ + "] " + key + " " + what + line_of(n), origin_, hint);
  }
  const toml::table& t_;
  std::string stage_;
  fs::path origin_;
  std::vector<std::string> known_;
};

class JsonWriter final : public Visitor {
 public:
  nlohmann::json j = nlohmann::json::object();
  void number(const char* key, double& v, double, double, const char*, const char*) override { j[key] = v; }
  void integer(const char* key, int& v, int, int, const char*) override { j[key] = v; }
  void boolean(const char* key, bool& v, const char*) override { j[key] = v; }
  void choice(const char* key, std::string& v, const std::vector<std::string>&, const char*) override { j[key] = v; }
  void subset(const char* key, std::vector<std::string>& v, const std::vector<std::string>&, const char*) override {
    j[key] = v;
  }
  void names(const char* key, std::vector<std::string>& v, const char*, const char*) override { j[key] = v; }
  void per_organ(const char* key, std::map<std::string, double>& v, double, double, const char*, const char*) override {
    j[key] = v.empty() ? nlohmann::json::object() : nlohmann::json(v);
  }
  void point(const char* key, std::vector<double>& v, const char*) override { j[key] = v.empty() ? nlohmann::json::array() : nlohmann::json(v); }
};

class TomlWriter final : public Visitor {
 public:
  std::ostringstream out;
  void number(const char* key, double& v, double lo, double hi, const char* unit, const char* doc) override {
    std::string value = format_g(v, 6);
    if (value.find_first_of(".e") == std::string::npos) value += ".0";  // stays a TOML float
    line(key, value, std::string(doc) + " (" + format_g(lo, 6) + "–" + format_g(hi, 6) + " " + unit + ")");
  }
  void integer(const char* key, int& v, int lo, int hi, const char* doc) override {
    line(key, std::to_string(v), std::string(doc) + " (" + std::to_string(lo) + "–" + std::to_string(hi) + ")");
  }
  void boolean(const char* key, bool& v, const char* doc) override { line(key, v ? "true" : "false", doc); }
  void choice(const char* key, std::string& v, const std::vector<std::string>& allowed, const char* doc) override {
    line(key, "\"" + v + "\"", std::string(doc) + "; one of " + join(allowed));
  }
  void subset(const char* key, std::vector<std::string>& v, const std::vector<std::string>& allowed,
              const char* doc) override {
    std::vector<std::string> quoted;
    for (const auto& s : v) quoted.push_back("\"" + s + "\"");
    line(key, "[" + join(quoted) + "]", std::string(doc) + "; any of " + join(allowed));
  }
  void names(const char* key, std::vector<std::string>& v, const char* what, const char* doc) override {
    std::vector<std::string> quoted;
    for (const auto& s : v) quoted.push_back("\"" + s + "\"");
    line(key, "[" + join(quoted) + "]", std::string(doc) + "; " + what + " names from the organ registry");
  }
  void per_organ(const char* key, std::map<std::string, double>& v, double lo, double hi, const char* unit,
                 const char* doc) override {
    std::vector<std::string> items;
    for (const auto& [organ, x] : v) items.push_back(organ + " = " + format_g(x, 6));
    line(key, "{ " + join(items) + (items.empty() ? "}" : " }"),
         std::string(doc) + " (" + format_g(lo, 6) + "–" + format_g(hi, 6) + " " + unit + ")");
  }
  void point(const char* key, std::vector<double>& v, const char* doc) override {
    std::vector<std::string> items;
    for (double x : v) items.push_back(format_g(x, 6));
    line(key, "[" + join(items) + "]", doc);
  }

 private:
  void line(const char* key, const std::string& value, const std::string& comment) {
    std::string kv = std::string(key) + " = " + value;
    if (kv.size() < 34) kv.resize(34, ' ');
    out << kv << " # " << comment << "\n";
  }
};

}  // namespace

const std::vector<std::string>& configurable_stages() {
  static const std::vector<std::string> names = {"segment", "mesh", "attach", "guide", "simulate", "snapshot"};
  return names;
}

std::string nearest_key(const std::string& key, const std::vector<std::string>& valid) {
  std::string best;
  std::size_t best_d = std::string::npos;
  for (const auto& v : valid) {
    // Levenshtein distance, one row at a time.
    std::vector<std::size_t> row(v.size() + 1);
    for (std::size_t j = 0; j <= v.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= key.size(); ++i) {
      std::size_t diag = row[0];
      row[0] = i;
      for (std::size_t j = 1; j <= v.size(); ++j) {
        const std::size_t up = row[j];
        row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (key[i - 1] == v[j - 1] ? 0 : 1)});
        diag = up;
      }
    }
    if (row[v.size()] < best_d) best_d = row[v.size()], best = v;
  }
  return best;
}

StageOptions parse_stage_options(const toml::table* stages, const fs::path& origin) {
  StageOptions o;
  if (!stages) return o;
  for (const auto& [k, node] : *stages) {
    const std::string name(k.str());
    const auto& known = configurable_stages();
    if (std::find(known.begin(), known.end(), name) == known.end())
      throw CaseFileError("unknown stage '" + name + "' in [stages]" + line_of(node), origin,
                          "did you mean '" + nearest_key(name, known) + "'? stages: " + join(known));
    if (!node.is_table())
      throw CaseFileError("[stages] " + name + " must be a table" + line_of(node), origin,
                          "write it as [stages." + name + "] followed by its keys");
  }
  for_each_stage(o, [&](const char* name, auto&& fields) {
    const toml::table* t = (*stages)[name].as_table();
    if (!t) return;
    Parser p(*t, name, origin);
    if constexpr (!std::is_same_v<std::decay_t<decltype(fields)>, std::nullptr_t>) fields(p);
    p.reject_unknown(std::string(name) == "segment" ? std::set<std::string>{"presets"} : std::set<std::string>{});
  });
  return o;
}

nlohmann::json stage_options_json(const StageOptions& options, const std::string& stage) {
  StageOptions o = options;  // the visitors take fields by reference
  nlohmann::json j = nlohmann::json::object();
  for_each_stage(o, [&](const char* name, auto&& fields) {
    if (stage != name) return;
    JsonWriter w;
    if constexpr (!std::is_same_v<std::decay_t<decltype(fields)>, std::nullptr_t>) fields(w);
    j = w.j;
  });
  return j;
}

std::string describe_stage_options() {
  StageOptions o;
  std::ostringstream out;
  out << "# Options of each stage: every key with its default; drop a key to keep its default.\n";
  for_each_stage(o, [&](const char* name, auto&& fields) {
    if constexpr (!std::is_same_v<std::decay_t<decltype(fields)>, std::nullptr_t>) {
      TomlWriter w;
      fields(w);
      out << "\n[stages." << name << "]\n" << w.out.str();
    } else if (std::string(name) == "segment") {
      out << "\n[stages.segment]\n# [stages.segment.presets.<organ>] overrides any organ preset key; "
             "`organsmith segment --print-presets` lists them\n";
    }
  });
  return out.str();
}

}  // namespace organsmith
