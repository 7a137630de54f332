#include "core/vtk_xml.h"

#include "core/format.h"

#include <algorithm>
#include <cassert>

namespace organsmith {

namespace {

std::string real(double v, int decimals) { return decimals >= 0 ? format_fixed(v, decimals) : format_shortest(v); }

bool integral(const std::string& type) { return type != "Float64" && type != "Float32"; }

/// `values` as tuples of `components`, one tuple per line.
template <class T, class Format>
void put_tuples(std::string& s, const std::vector<T>& values, int components, Format&& format) {
  for (std::size_t i = 0; i < values.size(); i += std::size_t(components)) {
    s += "          ";
    for (int k = 0; k < components && i + std::size_t(k) < values.size(); ++k)
      s += (k ? " " : "") + format(values[i + std::size_t(k)]);
    s += "\n";
  }
}

void put_array(std::string& s, const VtkArray& a, const std::string& extra = {}) {
  s += "        <DataArray type=\"" + a.type + "\" Name=\"" + xml_escape(a.name) + "\"";
  if (a.components != 1) s += " NumberOfComponents=\"" + std::to_string(a.components) + "\"";
  s += extra + " format=\"ascii\">\n";
  if (integral(a.type))
    put_tuples(s, a.values, a.components, [](double v) { return std::to_string(static_cast<long long>(v)); });
  else
    put_tuples(s, a.values, a.components, [&](double v) { return real(v, a.decimals); });
  s += "        </DataArray>\n";
}

void put_group(std::string& s, const char* tag, const std::vector<VtkArray>& arrays) {
  if (arrays.empty()) return;
  s += std::string("      <") + tag + " Scalars=\"" + xml_escape(arrays.front().name) + "\">\n";
  for (const auto& a : arrays) put_array(s, a);
  s += std::string("      </") + tag + ">\n";
}

/// The cells: connectivity with one cell per line, then the offsets.
void put_cells(std::string& s, const VtkPiece& p) {
  s += "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
  std::size_t begin = 0;
  for (const auto end : p.offsets) {
    s += "         ";
    for (std::size_t i = begin; i < std::size_t(end); ++i) s += " " + std::to_string(p.connectivity[i]);
    s += "\n";
    begin = std::size_t(end);
  }
  s += "        </DataArray>\n        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  for (const auto end : p.offsets) s += "          " + std::to_string(end) + "\n";
  s += "        </DataArray>\n";
}

std::string head(const char* type, const VtkPiece& p, const std::string& comment) {
  std::string s = "<?xml version=\"1.0\"?>\n";
  if (!comment.empty()) s += "<!-- " + comment + " -->\n";
  s += std::string("<VTKFile type=\"") + type + "\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n";
  s += std::string("  <") + type + ">\n";
  if (!p.field_data.empty()) {
    s += "    <FieldData>\n";
    for (const auto& a : p.field_data)
      put_array(s, a, " NumberOfTuples=\"" + std::to_string(a.values.size() / std::size_t(std::max(1, a.components))) + "\"");
    s += "    </FieldData>\n";
  }
  return s;
}

void put_points_and_data(std::string& s, const VtkPiece& p) {
  put_group(s, "PointData", p.point_data);
  put_group(s, "CellData", p.cell_data);
  s += "      <Points>\n        <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (const auto& q : p.points)
    s += "          " + real(q.x(), p.point_decimals) + " " + real(q.y(), p.point_decimals) + " " +
         real(q.z(), p.point_decimals) + "\n";
  s += "        </DataArray>\n      </Points>\n";
}

}  // namespace

std::string xml_escape(const std::string& in) {
  std::string o;
  for (char c : in) {
    switch (c) {
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '&': o += "&amp;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

std::string vtk_polydata_xml(const VtkPiece& p, VtkPolyCells cells, const std::string& comment) {
  const std::string n = std::to_string(p.offsets.size());
  const bool lines = cells == VtkPolyCells::lines;
  std::string s = head("PolyData", p, comment);
  s += "    <Piece NumberOfPoints=\"" + std::to_string(p.points.size()) + "\" NumberOfVerts=\"0\" NumberOfLines=\"" +
       (lines ? n : "0") + "\" NumberOfStrips=\"0\" NumberOfPolys=\"" + (lines ? "0" : n) + "\">\n";
  put_points_and_data(s, p);
  const char* tag = lines ? "Lines" : "Polys";
  s += std::string("      <") + tag + ">\n";
  put_cells(s, p);
  s += std::string("      </") + tag + ">\n    </Piece>\n  </PolyData>\n</VTKFile>\n";
  return s;
}

std::string vtk_unstructured_xml(const VtkPiece& p, const std::string& comment) {
  assert(p.cell_types.size() == p.offsets.size());
  std::string s = head("UnstructuredGrid", p, comment);
  s += "    <Piece NumberOfPoints=\"" + std::to_string(p.points.size()) + "\" NumberOfCells=\"" +
       std::to_string(p.offsets.size()) + "\">\n";
  put_points_and_data(s, p);
  s += "      <Cells>\n";
  put_cells(s, p);
  s += "        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (auto t : p.cell_types) s += "          " + std::to_string(int(t)) + "\n";
  s += "        </DataArray>\n      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n";
  return s;
}

}  // namespace organsmith
