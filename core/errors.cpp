#include "core/errors.h"

namespace organsmith {

namespace {
std::string compose(const std::string& message, const std::filesystem::path& path,
                    const std::string& hint) {
  std::string s = message;
  if (!path.empty()) s += " [" + path.string() + "]";
  if (!hint.empty()) s += " — " + hint;
  return s;
}
}  // namespace

Error::Error(ExitCode code, std::string message, std::filesystem::path path, std::string hint)
    : std::runtime_error(compose(message, path, hint)),
      code_(code),
      message_(std::move(message)),
      path_(std::move(path)),
      hint_(std::move(hint)) {}

}  // namespace organsmith
