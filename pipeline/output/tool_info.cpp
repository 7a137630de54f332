#include "pipeline/output/tool_info.h"

#include "organsmith_version.h"  // generated at build time: version and git commit

namespace organsmith {

std::string tool_version() { return ORGANSMITH_VERSION_STRING; }
std::string tool_git_commit() { return ORGANSMITH_GIT_COMMIT; }

}  // namespace organsmith
