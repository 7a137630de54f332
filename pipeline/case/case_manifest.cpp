// The case a manifest recorded, read back: to_json(CaseFile)'s reader. The JSON is turned into
// case-file TOML and parsed by parse_case, so that a case read back is validated exactly as one
// written by hand.

#include "core/errors.h"
#include "pipeline/case/case_file.h"
#include "pipeline/output/output_dir.h"
#include "pipeline/output/output_layout.h"

#include <toml++/toml.h>

#include <fstream>
#include <sstream>

namespace organsmith {

namespace fs = std::filesystem;

namespace {

/// A JSON value as a TOML node (objects → tables, arrays → arrays).
std::unique_ptr<toml::node> to_toml(const nlohmann::json& j) {
  if (j.is_object()) {
    auto t = std::make_unique<toml::table>();
    for (const auto& [k, v] : j.items())
      if (!v.is_null()) t->insert(k, std::move(*to_toml(v)));
    return t;
  }
  if (j.is_array()) {
    auto a = std::make_unique<toml::array>();
    for (const auto& v : j) a->push_back(std::move(*to_toml(v)));
    return a;
  }
  if (j.is_boolean()) return std::make_unique<toml::value<bool>>(j.get<bool>());
  if (j.is_number_integer()) return std::make_unique<toml::value<std::int64_t>>(j.get<std::int64_t>());
  if (j.is_number()) return std::make_unique<toml::value<double>>(j.get<double>());
  return std::make_unique<toml::value<std::string>>(j.is_string() ? j.get<std::string>() : j.dump());
}

}  // namespace

CaseFile case_from_manifest(const nlohmann::json& m, const fs::path& manifest_file) {
  if (!m.is_object() || !m.contains("case") || !m["case"].is_object())
    throw InputError(ExitCode::input_not_found, "the manifest records no case", manifest_file,
                     "this directory was not written by `organsmith run` or `organsmith segment`");
  const nlohmann::json& c = m["case"];
  try {
    nlohmann::json t = nlohmann::json::object();
    t["case"] = {{"name", c.at("name")}, {"input", c.at("input")}};
    if (c.contains("organ_registry")) t["case"]["organs"] = c["organ_registry"];
    nlohmann::json ph = c.at("phantom");
    ph["size"] = ph.at("size_vox");
    ph.erase("size_vox");
    t["phantom"] = ph;
    nlohmann::json in = c.at("ingest");
    in.erase("gap_factor");  // derived, not a case key
    t["ingest"] = in;
    t["organ"] = c.at("organs");
    t["output"] = c.at("output");
    if (c.contains("materials")) t["materials"] = c["materials"];
    nlohmann::json stages = c.value("stages", nlohmann::json::object());
    if (stages.contains("segment") && stages["segment"].value("presets", nlohmann::json::object()).empty())
      stages.erase("segment");
    t["stages"] = stages;
    std::ostringstream text;
    text << toml::toml_formatter{*static_cast<toml::table*>(to_toml(t).get())};
    return parse_case(text.str(), manifest_file);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(ExitCode::unsupported_input, std::string("the manifest's case is incomplete: ") + e.what(),
                     manifest_file, "rerun the case (`organsmith run`) into this directory");
  }
}

std::optional<CaseFile> case_of_run(const fs::path& dir) {
  const std::optional<nlohmann::json> m = read_manifest(dir);
  if (!m || !m->contains("case")) return std::nullopt;
  CaseFile c = case_from_manifest(*m, OutputLayout{dir}.manifest());
  c.out_dir = dir;
  return c;
}

}  // namespace organsmith
