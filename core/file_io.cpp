#include "core/file_io.h"

#include "core/errors.h"

#include <unistd.h>

#include <fstream>
#include <iterator>
#include <string>

namespace organsmith {

std::optional<std::string> read_file(const std::filesystem::path& path) {
  // A directory opens as a stream on Linux and fails only when read (libstdc++ then throws from
  // its underflow): refuse it here, and any other read error with it.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return std::nullopt;
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  try {
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) return std::nullopt;
    return bytes;
  } catch (const std::ios_base::failure&) {
    return std::nullopt;
  }
}

std::string read_input_file(const std::filesystem::path& path, const std::string& what, ExitCode too_big,
                            const std::string& hint, std::uintmax_t max_bytes) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw InputError(ExitCode::input_not_found, what + " is a directory, not a file", path, hint);
  if (const std::uintmax_t bytes = std::filesystem::file_size(path, ec); !ec && bytes > max_bytes)
    throw InputError(too_big,
                     what + " is " + std::to_string(bytes >> 20) + " MiB, more than the limit of " +
                         std::to_string(max_bytes >> 20) + " MiB",
                     path, hint);
  // Read with the limit too: a device or a pipe has no size to check first.
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(ExitCode::input_not_found, "cannot read " + what, path, hint);
  std::string text;
  char chunk[1 << 16];
  while (in.read(chunk, sizeof chunk) || in.gcount() > 0) {
    text.append(chunk, std::size_t(in.gcount()));
    if (text.size() > max_bytes)
      throw InputError(too_big, what + " holds more than the limit of " + std::to_string(max_bytes >> 20) + " MiB",
                       path, hint);
  }
  if (in.bad()) throw InputError(ExitCode::input_not_found, "cannot read " + what, path, hint);
  return text;
}

void write_file_atomic(const std::filesystem::path& path, std::string_view bytes) {
  namespace fs = std::filesystem;
  // The process id keeps two writers of the same path from sharing a temporary file.
  const fs::path tmp = path.parent_path() / ("." + path.filename().string() + ".tmp" + std::to_string(::getpid()));
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw OutputError("cannot create the file", tmp, "check that the directory exists and is writable");
    out.write(bytes.data(), std::streamsize(bytes.size()));
    out.flush();
    if (!out) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throw OutputError("cannot write the file", path, "check that the directory is writable and the disk not full");
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw OutputError("cannot move the file into place: " + ec.message(), path,
                      "check the permissions of the output directory");
  }
}

}  // namespace organsmith
