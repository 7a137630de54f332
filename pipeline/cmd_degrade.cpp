// Placeholder while the command is being written.
#include "pipeline/commands.h"

namespace organsmith {

std::vector<Command> degradation_commands(CLI::App&) { return {}; }

}  // namespace organsmith
