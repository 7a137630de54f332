// `segment` subcommand: registered here when its module lands.

#include "pipeline/commands.h"

namespace organsmith {

std::vector<Command> segmentation_commands(CLI::App&) { return {}; }

}  // namespace organsmith
