// VTK XML meshes → core types.

#include "viewer/mesh_files.h"

#include "core/errors.h"

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLPolyDataReader.h>
#include <vtkXMLUnstructuredGridReader.h>

namespace organsmith {
namespace {

vtkDataArray* region_array(vtkDataSet* ds) {
  for (const char* name : {"region", "region_id", "region_ids", "RegionId", "regions"})
    if (vtkDataArray* a = ds->GetCellData()->GetArray(name); a && a->GetNumberOfComponents() == 1) return a;
  return nullptr;
}

std::vector<Eigen::Vector3d> points_of(vtkPointSet* ds) {
  std::vector<Eigen::Vector3d> pts(std::size_t(ds->GetNumberOfPoints()));
  for (vtkIdType i = 0; i < ds->GetNumberOfPoints(); ++i) ds->GetPoint(i, pts[std::size_t(i)].data());
  return pts;
}

}  // namespace

MeshFileContents read_mesh_file(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw InputError(ExitCode::input_not_found, "no such mesh file", path);
  MeshFileContents out;
  const std::string ext = path.extension().string();
  if (ext == ".vtp") {
    auto reader = vtkSmartPointer<vtkXMLPolyDataReader>::New();
    if (!reader->CanReadFile(path.string().c_str()))
      throw InputError(ExitCode::unsupported_input, "not a VTK XML polydata file", path);
    reader->SetFileName(path.string().c_str());
    reader->Update();
    vtkPolyData* pd = reader->GetOutput();
    out.surface.vertices_lps_mm = points_of(pd);
    vtkDataArray* regions = region_array(pd);
    // Cell ids of a vtkPolyData run through verts, lines, polys, strips in that order.
    const vtkIdType first_poly = pd->GetNumberOfVerts() + pd->GetNumberOfLines();
    vtkIdType cell = first_poly;
    const vtkIdType* ids = nullptr;
    vtkIdType n = 0;
    vtkCellArray* polys = pd->GetPolys();
    for (polys->InitTraversal(); polys->GetNextCell(n, ids); ++cell)
      for (vtkIdType c = 1; c + 1 < n; ++c) {
        out.surface.triangles.push_back({std::int32_t(ids[0]), std::int32_t(ids[c]), std::int32_t(ids[c + 1])});
        if (regions) out.surface.region_ids.push_back(std::int32_t(regions->GetTuple1(cell)));
      }
    vtkCellArray* lines = pd->GetLines();
    for (lines->InitTraversal(); lines->GetNextCell(n, ids);) {
      Polyline pl;
      pl.name = path.stem().string();
      for (vtkIdType c = 0; c < n; ++c) pl.points_lps_mm.push_back(out.surface.vertices_lps_mm[std::size_t(ids[c])]);
      if (n > 2 && ids[0] == ids[n - 1]) {
        pl.closed = true;
        pl.points_lps_mm.pop_back();
      }
      out.lines.push_back(std::move(pl));
    }
    if (out.surface.triangles.empty()) out.surface.vertices_lps_mm.clear();
  } else if (ext == ".vtu") {
    auto reader = vtkSmartPointer<vtkXMLUnstructuredGridReader>::New();
    if (!reader->CanReadFile(path.string().c_str()))
      throw InputError(ExitCode::unsupported_input, "not a VTK XML unstructured-grid file", path);
    reader->SetFileName(path.string().c_str());
    reader->Update();
    vtkUnstructuredGrid* ug = reader->GetOutput();
    out.tets.vertices_lps_mm = points_of(ug);
    vtkDataArray* regions = region_array(ug);
    auto ids = vtkSmartPointer<vtkIdList>::New();
    for (vtkIdType c = 0; c < ug->GetNumberOfCells(); ++c) {
      if (ug->GetCellType(c) != VTK_TETRA) continue;
      ug->GetCellPoints(c, ids);
      out.tets.tets.push_back({std::int32_t(ids->GetId(0)), std::int32_t(ids->GetId(1)), std::int32_t(ids->GetId(2)),
                               std::int32_t(ids->GetId(3))});
      out.tets.region_ids.push_back(regions ? std::int32_t(regions->GetTuple1(c)) : 0);
    }
  } else {
    throw InputError(ExitCode::unsupported_input, "not a .vtp or .vtu mesh file", path,
                     "the viewer reads VTK XML meshes; other formats are for simulators");
  }
  return out;
}

}  // namespace organsmith
