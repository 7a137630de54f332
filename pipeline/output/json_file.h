#pragma once
// Reading a JSON file another stage or command may or may not have left in a directory.

#include <nlohmann/json.hpp>

#include <filesystem>

namespace organsmith {

/// The JSON of `p`, or null when it is absent or not JSON (a warning says so).
nlohmann::json read_json_or_null(const std::filesystem::path& p);

}  // namespace organsmith
