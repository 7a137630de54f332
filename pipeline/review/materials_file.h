#pragma once
// materials.json of the attach stage, through its one reader: each organ region's calibrated law
// (used by the snapshot's plots, `haptics`, `preview` and the run's model in memory).

#include "core/material.h"
#include "physics/materials/models.h"
#include "pipeline/case/organ_registry.h"

#include <filesystem>
#include <map>
#include <optional>
#include <string>

namespace organsmith {

/// The calibrated law of an organ region ("gallbladder_body", "trachea_wall", …): from
/// OUT/materials.json (the attach stage) when it has the region, else the built-in preset the
/// region is assigned to. Throws InputError when materials.json is malformed or no law exists.
struct OutputRegionLaw {
  Material material;
  physics::ModelOptions options;
  std::string preset_id;     ///< the preset it came from (as materials.json records it)
  bool from_output = false;  ///< true: read from OUT/materials.json
};

/// materials.json (the attach stage) as its one reader gives it: each region's law, or what is
/// wrong with the region's entry.
struct MaterialsFile {
  std::filesystem::path source;                       ///< the file (named in errors)
  std::map<std::string, OutputRegionLaw> regions;     ///< by region name
  std::map<std::string, std::string> malformed;       ///< region → what is wrong with its entry
};
/// Reads materials.json's text (`source` names it); throws InputError when the text is not JSON.
MaterialsFile materials_from_text(const std::string& text, const std::filesystem::path& source);
/// OUT/materials.json through that reader: nothing when the file is absent.
std::optional<MaterialsFile> read_materials(const std::filesystem::path& out);
/// The law of `region`: from `materials` when it has the region (InputError when its entry is
/// malformed), else the built-in preset the registry assigns (InputError when there is none).
OutputRegionLaw output_region_law(const MaterialsFile* materials, const std::string& region, const OrganRegistry& registry,
                                  const std::filesystem::path& materials_path);

}  // namespace organsmith
