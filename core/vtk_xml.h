#pragma once
// VTK XML files in ASCII: PolyData (.vtp) and UnstructuredGrid (.vtu). The one writer for every
// module that writes them (organ meshes, guidance paths, the clip's degradation stages); VTK
// itself is linked by the viewer only, which reads these files back with VTK's own readers.

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace organsmith {

/// A named data array: `components` values per tuple, tuples one after another. Types Int32,
/// Int64 and UInt8 are written as integers; Float64 as the shortest text that reads back the same
/// double, or with `decimals` fixed decimals when that is ≥ 0.
struct VtkArray {
  std::string name;
  std::string type = "Float64";
  int components = 1;
  std::vector<double> values;
  int decimals = -1;
};

/// One piece: points, cells (flat connectivity with each cell's end offset, as VTK stores them),
/// and the arrays on points, on cells and on the whole data set. The first point and cell
/// arrays are the active scalars.
struct VtkPiece {
  std::vector<Eigen::Vector3d> points;
  int point_decimals = -1;                  ///< as VtkArray::decimals, for the coordinates
  std::vector<std::int64_t> connectivity;   ///< point ids of every cell, one cell after another
  std::vector<std::int64_t> offsets;        ///< end of each cell in `connectivity`
  std::vector<std::uint8_t> cell_types;     ///< UnstructuredGrid only: VTK cell type per cell
  std::vector<VtkArray> point_data, cell_data, field_data;

  /// Appends a cell of these point ids.
  template <class Ids>
  void add_cell(const Ids& ids) {
    for (auto id : ids) connectivity.push_back(static_cast<std::int64_t>(id));
    offsets.push_back(static_cast<std::int64_t>(connectivity.size()));
  }
};

/// What PolyData cells are: lines (polylines) or polygons.
enum class VtkPolyCells { lines, polys };

/// The text of a .vtp file; `comment` (one line, may be empty) follows the XML declaration.
std::string vtk_polydata_xml(const VtkPiece& piece, VtkPolyCells cells, const std::string& comment);

/// `text` with the characters XML gives a meaning (< > & ") escaped, for attributes and comments.
std::string xml_escape(const std::string& text);

/// The text of a .vtu file; every cell needs its type in piece.cell_types.
std::string vtk_unstructured_xml(const VtkPiece& piece, const std::string& comment);

}  // namespace organsmith
