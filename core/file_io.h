#pragma once
// Writing files so that readers never see half of one.

#include <filesystem>
#include <string_view>

namespace organsmith {

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, then a rename.
/// Throws OutputError naming the path (nothing is left behind on failure).
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

}  // namespace organsmith
