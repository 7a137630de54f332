#include "pipeline/output/json_file.h"

#include <spdlog/spdlog.h>

#include <fstream>

namespace organsmith {

nlohmann::json read_json_or_null(const std::filesystem::path& p) {
  std::ifstream in(p);
  if (!in) return nullptr;
  try {
    return nlohmann::json::parse(in);
  } catch (const std::exception&) {
    spdlog::warn("{} is not valid JSON; ignored", p.string());
    return nullptr;
  }
}

}  // namespace organsmith
