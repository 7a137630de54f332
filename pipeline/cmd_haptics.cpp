// Placeholder while the command is being written.
#include "pipeline/commands.h"

namespace organsmith {

std::vector<Command> haptics_commands(CLI::App&) { return {}; }

}  // namespace organsmith
