// `snapshot` and `preview` subcommands: registered here when the viewer lands.

#include "pipeline/commands.h"

namespace organsmith {

std::vector<Command> viewer_commands(CLI::App&) { return {}; }

}  // namespace organsmith
