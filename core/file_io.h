#pragma once
// Reading a file whole; writing files so that readers never see half of one.

#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace organsmith {

/// The file's bytes, or nothing when it cannot be opened (the caller names the file and says
/// what to do in its own error).
std::optional<std::string> read_file(const std::filesystem::path& path);

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, then a rename.
/// Throws OutputError naming the path (nothing is left behind on failure).
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

}  // namespace organsmith
