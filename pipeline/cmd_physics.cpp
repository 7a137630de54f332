// Physics subcommands (calibrate, uncertainty, materials): registered here as they land.

#include "pipeline/commands.h"

namespace organsmith {

std::vector<Command> physics_commands(CLI::App&) { return {}; }

}  // namespace organsmith
