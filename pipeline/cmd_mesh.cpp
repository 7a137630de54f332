// `mesh` subcommand: registered here when its module lands.

#include "pipeline/commands.h"

namespace organsmith {

std::vector<Command> meshing_commands(CLI::App&) { return {}; }

}  // namespace organsmith
