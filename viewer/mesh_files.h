#pragma once
// Reads the VTK XML meshes other stages write (.vtp surfaces and paths, .vtu tetrahedra) into
// core types, so that views can be made from an output directory.

#include "core/geometry.h"

#include <filesystem>
#include <vector>

namespace organsmith {

/// What one VTK XML file holds, in core types (coordinates taken as LPS mm, as organsmith writes them).
struct MeshFileContents {
  SurfaceMesh surface;             ///< triangles of a .vtp (polygons with > 3 corners are fanned)
  std::vector<Polyline> lines;     ///< line cells of a .vtp, one polyline each
  TetMesh tets;                    ///< tetrahedra of a .vtu (other cell types are skipped)
};

/// Reads a .vtp or .vtu file. Region ids come from the first integer cell array named
/// "region", "region_id", "region_ids", "RegionId" or "regions", when there is one.
/// Throws InputError when the file is missing or unreadable.
MeshFileContents read_mesh_file(const std::filesystem::path& path);

}  // namespace organsmith
