#pragma once
// organsmith's version and the git commit it was built from (manifests, reports, --version).

#include <string>

namespace organsmith {

std::string tool_version();
std::string tool_git_commit();

}  // namespace organsmith
