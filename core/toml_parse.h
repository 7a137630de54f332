#pragma once
// Parsing a TOML text with the project's error: one wrapper for the case file, the organ
// presets, the material library and the clip presets. Header-only; include it only from a
// translation unit that links toml++ (PkgConfig::TOMLPP).

#include "core/errors.h"

#include <toml++/toml.h>

#include <filesystem>
#include <string>
#include <string_view>

namespace organsmith {

/// Parses `text`; on a syntax error throws CaseFileError (exit 20)
/// "<what> is not valid TOML at line N: <description>" naming `source` (may be empty), with `hint`.
inline toml::table parse_toml(std::string_view text, const std::filesystem::path& source, const std::string& what,
                              std::string hint) {
  try {
    return toml::parse(text, source.string());
  } catch (const toml::parse_error& e) {
    throw CaseFileError(what + " is not valid TOML at line " + std::to_string(e.source().begin.line) + ": " +
                            std::string(e.description()),
                        source, std::move(hint));
  }
}

}  // namespace organsmith
