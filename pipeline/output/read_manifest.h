#pragma once
// The one reader of an output directory's manifest.json (its own file so that the case-file
// parser, the registry and the fuzz target link it without the output-directory machinery).

#include <nlohmann/json.hpp>

#include <filesystem>
#include <optional>

namespace organsmith {

/// The manifest of the output directory `out_dir` (OutputLayout::manifest()), parsed: nothing when
/// it is absent, unreadable or not a JSON object. The one reader of another run's manifest.
std::optional<nlohmann::json> read_manifest(const std::filesystem::path& out_dir);

}  // namespace organsmith
