#pragma once
// Reading [stages] from a parsed case file (toml++ stays inside pipeline/case/case_file.cpp and
// pipeline/case/stage_options.cpp).

#include "pipeline/case/stage_options.h"

#include <toml++/toml.h>

namespace organsmith {

/// Reads the [stages] table (may be null). Unknown stages or keys, wrong types and values out of
/// range throw CaseFileError (exit 20) naming `origin`, the line, the key and the nearest valid
/// key or the allowed range. [stages.segment.presets] is checked by the caller.
StageOptions parse_stage_options(const toml::table* stages, const std::filesystem::path& origin);

}  // namespace organsmith
