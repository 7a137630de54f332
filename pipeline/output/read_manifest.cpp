#include "pipeline/output/read_manifest.h"

#include "core/file_io.h"
#include "pipeline/output/output_layout.h"

namespace organsmith {

std::optional<nlohmann::json> read_manifest(const std::filesystem::path& out_dir) {
  const auto text = read_file(OutputLayout{out_dir}.manifest());
  if (!text) return std::nullopt;
  try {
    nlohmann::json m = nlohmann::json::parse(*text);
    if (m.is_object() && m.contains("tool") && m["tool"].is_object() && m["tool"].value("name", "") == "organsmith" &&
        m.contains("stages") && m["stages"].is_array())
      return m;
  } catch (const nlohmann::json::exception&) {
  }
  return std::nullopt;
}

}  // namespace organsmith
