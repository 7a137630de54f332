#pragma once
// Reading a file whole; writing files so that readers never see half of one.

#include "core/errors.h"

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace organsmith {

/// The file's bytes, or nothing when it cannot be opened (the caller names the file and says
/// what to do in its own error).
std::optional<std::string> read_file(const std::filesystem::path& path);

/// The largest table or text a user gives that organsmith reads whole (calibration curves,
/// trajectories, recorded paths, cohort files, mass series, presets): 64 MiB, far above any real
/// one (tests of a tissue are hundreds to thousands of rows; an hour of trajectory at 1 kHz ~100 MB
/// is refused by its own span limit first).
inline constexpr std::uintmax_t kMaxTextInputBytes = std::uintmax_t(64) << 20;

/// A user's input file, read whole; `what` names it in errors ("the trajectory file"). Throws
/// InputError input_not_found (exit 3) when it is missing, a directory or unreadable, and
/// InputError `too_big` naming the limit when it is larger than `max_bytes` (checked before
/// anything is read or allocated).
std::string read_input_file(const std::filesystem::path& path, const std::string& what, ExitCode too_big,
                            const std::string& hint, std::uintmax_t max_bytes = kMaxTextInputBytes);

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, then a rename.
/// Throws OutputError naming the path (nothing is left behind on failure).
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);

}  // namespace organsmith
