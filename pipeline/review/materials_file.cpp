#include "pipeline/review/materials_file.h"

#include "core/errors.h"
#include "core/file_io.h"
#include "pipeline/output/output_layout.h"

#include <nlohmann/json.hpp>

namespace organsmith {

namespace fs = std::filesystem;

MaterialsFile materials_from_text(const std::string& text, const fs::path& source) {
  MaterialsFile m;
  m.source = source;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(ExitCode::unsupported_input, std::string("materials.json is not valid JSON: ") + e.what(), source,
                     "rerun the attach stage (`organsmith run --force`)");
  }
  if (!j.is_object() || !j.contains("regions") || !j["regions"].is_object()) return m;
  for (const auto& [region, r] : j["regions"].items()) {
    OutputRegionLaw law;
    try {
      law.material.model = r.at("model").get<std::string>();
      for (const auto& p : r.at("parameters"))
        law.material.parameters.push_back({p.at("name").get<std::string>(), p.at("value").get<double>(), p.value("unit", "")});
      if (r.contains("constants") && r["constants"].contains("bulk_modulus_Pa"))
        law.options.bulk_modulus_Pa = r["constants"]["bulk_modulus_Pa"].get<double>();
      law.preset_id = r.value("preset", std::string());
      law.material.source = r.value("source", std::string());
    } catch (const nlohmann::json::exception& e) {
      m.malformed[region] = e.what();
      continue;
    }
    law.from_output = true;
    m.regions[region] = std::move(law);
  }
  return m;
}

std::optional<MaterialsFile> read_materials(const fs::path& out) {
  const fs::path mf = OutputLayout{out}.materials();
  if (!fs::exists(mf)) return std::nullopt;
  const std::optional<std::string> text = read_file(mf);
  if (!text)
    throw InputError(ExitCode::input_not_found, "cannot read materials.json", mf, "check the file's permissions");
  return materials_from_text(*text, mf);
}

OutputRegionLaw output_region_law(const MaterialsFile* materials, const std::string& region, const OrganRegistry& registry,
                                  const fs::path& materials_path) {
  if (materials) {
    if (const auto it = materials->malformed.find(region); it != materials->malformed.end())
      throw InputError(ExitCode::unsupported_input, "region " + region + " of materials.json is malformed: " + it->second,
                       materials->source, "rerun the attach stage (`organsmith run --force`)");
    if (const auto it = materials->regions.find(region); it != materials->regions.end()) return it->second;
  }
  std::string preset_id;
  for (const auto& o : registry.organs)
    if (const auto it = o.materials.find(region); it != o.materials.end()) preset_id = it->second;
  if (preset_id.empty())
    throw InputError(ExitCode::unsupported_input, "no material for region " + region, materials_path,
                     "run the attach stage, or see `organsmith materials` for the regions");
  const physics::RegionLaw r = region_law(preset_id);
  OutputRegionLaw law;
  law.material = r.material;
  law.options = r.options;
  law.preset_id = preset_id;
  return law;
}


}  // namespace organsmith
