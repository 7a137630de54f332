// The mesh file formats organsmith writes (kept apart from the writers: the case-file parser
// checks [stages.mesh] formats with it).
#include "meshing/export.h"

namespace organsmith {

std::vector<std::string> all_mesh_formats() { return {"stl", "obj", "ply", "vtp", "vtu", "msh", "msh22", "inp", "feb"}; }

}  // namespace organsmith
