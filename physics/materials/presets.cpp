#include "physics/materials/presets.h"

#include "core/errors.h"
#include "core/toml_parse.h"
#include "materials_toml.h"  // generated from data/materials.toml

#include <toml++/toml.h>


namespace organsmith::physics {

namespace {

std::vector<MaterialParameter> read_named_numbers(const toml::table& t, const toml::table* units,
                                                  const std::filesystem::path& source,
                                                  const std::string& id) {
  std::vector<MaterialParameter> out;
  for (const auto& [key, node] : t) {
    const auto v = node.value<double>();
    if (!v)
      throw CaseFileError("material '" + id + "': '" + std::string(key.str()) + "' is not a number",
                          source);
    MaterialParameter p;
    p.name = std::string(key.str());
    p.value = *v;
    if (units) p.unit = (*units)[key.str()].value_or(std::string());
    out.push_back(std::move(p));
  }
  return out;
}

}  // namespace

const MaterialPreset& MaterialLibrary::find(const std::string& id) const {
  for (const auto& m : materials)
    if (m.id == id) return m;
  std::string known;
  for (const auto& m : materials) known += "\n  " + m.id;
  throw UsageError("no material preset '" + id + "'", "known presets:" + known);
}

const DerivativeTable& MaterialLibrary::table(const std::string& id) const {
  for (const auto& t : derivative_tables)
    if (t.id == id) return t;
  throw UsageError("no derivative table '" + id + "'");
}

MaterialLibrary parse_material_library(const std::string& text, const std::filesystem::path& source) {
  const toml::table root = parse_toml(text, source, "the materials file", "the file must be TOML like data/materials.toml");
  MaterialLibrary lib;
  if (const toml::array* arr = root["material"].as_array()) {
    for (const auto& node : *arr) {
      const toml::table* t = node.as_table();
      if (!t) throw CaseFileError("[[material]] entry is not a table", source);
      MaterialPreset p;
      p.id = (*t)["id"].value_or(std::string());
      p.material.model = (*t)["model"].value_or(std::string());
      p.material.source = (*t)["source"].value_or(std::string());
      if (p.id.empty() || p.material.model.empty())
        throw CaseFileError("a [[material]] entry lacks id or model", source);
      const toml::table* params = (*t)["parameters"].as_table();
      if (!params) throw CaseFileError("material '" + p.id + "' has no parameters", source);
      const toml::table* units = (*t)["units"].as_table();
      p.material.parameters = read_named_numbers(*params, units, source, p.id);
      for (const char* kind : {"sd", "dc_sd", "imvfosm_sd"})
        if (const toml::table* s = (*t)[kind].as_table())
          p.spreads[kind] = read_named_numbers(*s, units, source, p.id);
      for (const char* kind : {"constants", "fit"})
        if (const toml::table* s = (*t)[kind].as_table())
          for (const auto& q : read_named_numbers(*s, nullptr, source, p.id))
            (std::string(kind) == "fit" ? p.fit : p.constants)[q.name] = q.value;
      if (const auto sm = (*t)["stretch_max"].value<double>()) {
        p.stretch_max = *sm;
        if (!(p.stretch_max > 1.0 && p.stretch_max < 10.0))
          throw CaseFileError("material '" + p.id + "': stretch_max must lie in (1, 10)", source);
      }
      p.range_source = (*t)["range_source"].value_or(std::string());
      lib.materials.push_back(std::move(p));
    }
  }
  if (const toml::array* arr = root["derivative_table"].as_array()) {
    for (const auto& node : *arr) {
      const toml::table* t = node.as_table();
      if (!t) continue;
      DerivativeTable d;
      d.id = (*t)["id"].value_or(std::string());
      d.direction = (*t)["direction"].value_or(std::string());
      d.source = (*t)["source"].value_or(std::string());
      auto numbers = [&](const toml::array* a) {
        std::vector<double> v;
        if (a)
          for (const auto& x : *a) v.push_back(x.value<double>().value_or(std::nan("")));
        return v;
      };
      d.stretch = numbers((*t)["stretch"].as_array());
      d.sigma_T_Pa = numbers((*t)["sigma_T_Pa"].as_array());
      const toml::array* rows = (*t)["dfdC"].as_array();
      if (!rows || rows->size() != d.stretch.size() || d.sigma_T_Pa.size() != d.stretch.size())
        throw CaseFileError("derivative table '" + d.id + "': row counts disagree", source);
      d.dfdC.resize(static_cast<Eigen::Index>(rows->size()), 7);
      for (std::size_t i = 0; i < rows->size(); ++i) {
        const auto row = numbers((*rows)[i].as_array());
        if (row.size() != 7) throw CaseFileError("derivative table '" + d.id + "': rows need 7 values", source);
        for (int j = 0; j < 7; ++j) d.dfdC(static_cast<Eigen::Index>(i), j) = row[static_cast<std::size_t>(j)];
      }
      lib.derivative_tables.push_back(std::move(d));
    }
  }
  return lib;
}

MaterialLibrary builtin_material_library() {
  return parse_material_library(kMaterialsToml, "data/materials.toml (embedded)");
}

std::vector<double> parameter_values(const Model& model, const std::vector<MaterialParameter>& m) {
  std::vector<double> out;
  for (const auto& info : model.parameters()) {
    bool found = false;
    for (const auto& p : m)
      if (p.name == info.name) {
        out.push_back(p.value);
        found = true;
        break;
      }
    if (!found)
      throw UsageError("parameter '" + info.name + "' of " + std::string(model.name()) +
                       " is missing from the parameter set");
  }
  return out;
}

ModelOptions model_options_for(const MaterialPreset& preset, ModelOptions o) {
  if (auto it = preset.constants.find("bulk_modulus_Pa"); it != preset.constants.end())
    o.bulk_modulus_Pa = it->second;
  if (auto it = preset.constants.find("blade_speed_m_per_s"); it != preset.constants.end())
    o.blade_speed_m_per_s = it->second;
  return o;
}

}  // namespace organsmith::physics
